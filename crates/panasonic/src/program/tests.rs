use super::*;
use proptest::prelude::*;

#[test]
fn program_names_are_up_to_15_printable_characters_without_trailing_blanks() {
    assert_eq!(
        ProgramName::new("123456789ABC").map(|n| n.to_field()),
        Ok("P123456789ABC   ".to_owned())
    );
    assert_eq!(
        ProgramName::new("ABC   ").map(|n| n.as_str().to_owned()),
        Ok("ABC".to_owned())
    );
    assert_eq!(
        ProgramName::new(" A B").map(|n| n.as_str().to_owned()),
        Ok(" A B".to_owned())
    );
    assert_eq!(ProgramName::new("  "), Err(ProgramNameError::Empty));
    assert_eq!(
        ProgramName::new("0123456789ABCDEF"),
        Err(ProgramNameError::TooLong {
            name: "0123456789ABCDEF".into(),
            len: 16,
            max: 15
        })
    );
    assert_eq!(
        ProgramName::new("AB\tC"),
        Err(ProgramNameError::BadChar {
            name: "AB\tC".into(),
            offset: 2,
            found: '\t'
        })
    );
}

#[test]
fn program_field_of_the_c3_example_is_p_abc_padded_to_16() {
    // 3.3-12: D1 data size 16, data "PABC" + 12 blanks.
    let name = ProgramName::parse_field(b"PABC            ").expect("valid field");
    assert_eq!(name.as_str(), "ABC");
    let mut field = Vec::new();
    name.write_field(&mut field);
    assert_eq!(field, b"PABC            ");
    assert_eq!(field.len(), PROGRAM_FIELD_LEN);
    assert!(matches!(
        ProgramName::parse_field(b"LABC"),
        Err(ProgramNameError::NotAProduct { .. })
    ));
}

#[test]
fn targets_follow_the_identifier_letters() {
    let abc = ProgramName::new("123456789ABC").expect("valid");
    assert_eq!(
        Target::parse("P123456789ABC"),
        Ok(Target::Product(abc.clone()))
    );
    assert_eq!(Target::Product(abc).to_wire(), "P123456789ABC");
    assert_eq!(Target::parse("G"), Ok(Target::MachineData));
    assert_eq!(Target::parse("L"), Ok(Target::PartLibrary));
    assert_eq!(Target::parse("B"), Ok(Target::MarkLibrary));
    assert_eq!(Target::parse("V"), Ok(Target::NozzleLibrary));
    assert_eq!(Target::parse("Y"), Ok(Target::SupplyLibrary));
    assert_eq!(
        Target::parse("X"),
        Err(TargetError::UnknownKind { letter: 'X' })
    );
    assert_eq!(Target::parse(""), Err(TargetError::Missing));
    assert_eq!(
        Target::parse("P"),
        Err(TargetError::Name(ProgramNameError::Empty))
    );
    assert!(matches!(
        Target::parse("LFOO"),
        Err(TargetError::UnexpectedName { .. })
    ));
}

fn three_program_list() -> ProgramList {
    let entry = |y, m, d, name: &str| ProgramListEntry {
        date: ProgramDate::new(y, m, d).expect("valid date"),
        name: ProgramName::new(name).expect("valid name"),
    };
    ProgramList(vec![
        entry(3, 1, 30, "ABC"),
        entry(3, 2, 1, "BOARD-2"),
        entry(4, 12, 24, "123456789ABCDEF"),
    ])
}

#[test]
fn a_three_program_list_is_81_bytes_as_in_the_manual() {
    // 3.3-10: example size 81, data starting "03/01/30PABC".
    let bytes = three_program_list().to_bytes();
    assert_eq!(bytes.len(), 81);
    assert!(bytes.starts_with(b"03/01/30PABC            \r\n"));
    assert!(bytes.ends_with(b"*\r\n"));
    assert_eq!(ProgramList::parse(&bytes), Ok(three_program_list()));
}

#[test]
fn program_list_parsing_accepts_lf_and_unpadded_names_and_refuses_bad_lines() {
    assert_eq!(
        ProgramList::parse(b"03/01/30PABC\n*\n").map(|l| l.0.len()),
        Ok(1)
    );
    assert_eq!(ProgramList::parse(b"*\r\n"), Ok(ProgramList::default()));
    assert_eq!(
        ProgramList::parse(b"03/01/30PABC\r\n"),
        Err(ProgramListError::MissingEnd)
    );
    assert!(matches!(
        ProgramList::parse(b"03/01/30LABC\r\n*\r\n"),
        Err(ProgramListError::BadLine { line: 1, .. })
    ));
    assert!(matches!(
        ProgramList::parse(b"03/02/30PABC\r\n*\r\n"),
        Err(ProgramListError::BadDate { line: 1, .. })
    ));
    assert!(matches!(
        ProgramList::parse(b"short\r\n*\r\n"),
        Err(ProgramListError::BadLine { line: 1, .. })
    ));
    assert_eq!(
        ProgramList::parse(b"*\r\nmore\r\n"),
        Err(ProgramListError::TrailingData)
    );
}

#[test]
fn program_text_needs_the_end_mark_and_counts_entries_outside_the_header() {
    assert_eq!(
        ProgramText::new(b"%HEADER\r\nNAME=X\r\n".to_vec()),
        Err(ProgramTextError::MissingEnd { len: 17 })
    );
    assert!(
        ProgramText::new(b"x*\r\n".to_vec()).is_err(),
        "the end mark is a line of its own"
    );
    let text = ProgramText::new(
        b"%HEADER\r\nNAME=X\r\n%STEP\r\n1,0,0\r\n2,5,5\r\n\r\n&SUB\r\n3,1,1\r\n*\r\n".to_vec(),
    )
    .expect("valid text");
    assert_eq!(text.entries(), 3);
    assert_eq!(text.header_value("NAME"), Some("X".to_owned()));
    assert_eq!(text.header_value("MACHINE"), None);
    assert_eq!(
        ProgramText::new(END_MARK.to_vec()).map(|t| t.entries()),
        Ok(0)
    );
}

#[test]
fn condition_data_reads_the_manual_example_line() {
    // 3.3-4: "&CONDITIONDATA1" then "1010001,1,1,0,0".
    let data = b"%HEADER\r\nNAME=G\r\n&CONDITIONDATA1\r\n1010001,1,1,0,0\r\n*\r\n";
    let condition = ConditionData::parse(data).expect("valid machine data");
    assert_eq!(
        condition,
        ConditionData {
            pass_through: true,
            evaluation_mode: true,
            offset_manual_mark: false,
            evaluation_h_down: false
        }
    );
    assert_eq!(condition.line(), "1010001,1,1,0,0");
    assert_eq!(condition.to_text().as_bytes(), data);
    assert_eq!(
        ConditionData::parse(b"%HEADER\r\n*\r\n"),
        Err(ConditionDataError::Missing)
    );
    let bad_lines = [
        b"&CONDITIONDATA1\r\n1010001,1,2,0,0\r\n*\r\n".as_slice(),
        b"&CONDITIONDATA1\r\n1010002,1,1,0,0\r\n*\r\n",
    ]
    .map(ConditionData::parse);
    assert!(
        bad_lines
            .iter()
            .all(|e| matches!(e, Err(ConditionDataError::BadLine { .. }))),
        "{bad_lines:?}"
    );
}

proptest! {
    #[test]
    fn program_lists_round_trip(entries in prop::collection::vec((0u8..100, 1u8..13, 1u8..29, "[!-~][ -~]{0,13}[!-~]"), 0..20)) {
        let list = ProgramList(entries.into_iter().map(|(y, m, d, name)| ProgramListEntry {
            date: ProgramDate::new(y, m, d).expect("day below 29 is valid in every month"),
            name: ProgramName::new(&name).expect("printable, at most 15"),
        }).collect());
        let bytes = list.to_bytes();
        prop_assert_eq!(bytes.len(), list.0.len() * PROGRAM_LIST_ENTRY_LEN + 3);
        prop_assert_eq!(ProgramList::parse(&bytes), Ok(list));
    }

    #[test]
    fn program_names_round_trip_through_their_field(name in "[!-~][ -~]{0,14}") {
        let name = ProgramName::new(&name).expect("valid");
        let mut field = Vec::new();
        name.write_field(&mut field);
        prop_assert_eq!(field.len(), PROGRAM_FIELD_LEN);
        prop_assert_eq!(ProgramName::parse_field(&field), Ok(name.clone()));
        prop_assert_eq!(Target::parse(&Target::Product(name.clone()).to_wire()), Ok(Target::Product(name)));
    }
}
