use super::*;

fn problem(text: &str) -> MapError {
    SlaveMap::parse(text).expect_err("a bad map")
}

/// Asserts that the map `text` is refused with `message`.
fn says(text: &str, message: &str) {
    assert_eq!(problem(text).to_string(), message, "{text:?}");
}

#[test]
fn map_defines_each_table_and_the_unit() {
    let map = SlaveMap::parse(
        "# test map\n\
         unit 17\n\
         holding 0x0000 = 1 2 0xFF  # three registers\n\
         input 100 = 7 8\n\
         coil 10 = 1 0 1\n\
         \n\
         discrete 0x20 = 0 1\n\
         holding 0x1000..=0x10FF\n",
    )
    .expect("a good map");
    assert_eq!(map.unit().get(), 17);
    assert_eq!(map.get(Table::HoldingRegisters, 2), Some(0xFF));
    assert_eq!(map.get(Table::HoldingRegisters, 3), None);
    assert_eq!(map.get(Table::HoldingRegisters, 0x10FF), Some(0));
    assert_eq!(map.defined(Table::HoldingRegisters), 3 + 256);
    assert_eq!(map.get(Table::InputRegisters, 101), Some(8));
    assert_eq!(map.get(Table::Coils, 12), Some(1));
    assert_eq!(map.get(Table::Coils, 11), Some(0));
    assert_eq!(map.get(Table::DiscreteInputs, 0x21), Some(1));
    assert_eq!(map.get(Table::DiscreteInputs, 0x22), None);
}

#[test]
fn empty_map_is_unit_1_with_nothing_defined() {
    let map = SlaveMap::parse("").expect("empty is fine");
    assert_eq!(map.unit().get(), 1);
    assert!(Table::ALL.iter().all(|&t| map.defined(t) == 0));
}

#[test]
fn all_writable_map_has_every_address_zeroed() {
    let map = SlaveMap::all_writable(UnitId::new(5).expect("5"));
    for table in Table::ALL {
        assert_eq!(map.defined(table), 65536);
        assert_eq!(map.get(table, 0xFFFF), Some(0));
    }
}

#[test]
fn map_errors_name_the_line_and_the_problem() {
    assert_eq!(
        problem("holding 0 = 1\nholdin 1 = 2"),
        MapError {
            line: 2,
            problem: MapProblem::UnknownKeyword {
                word: "holdin".into()
            }
        }
    );
    says(
        "holding 0 = 1 2\nholding 1 = 5",
        "line 2: holding registers address 1 (0x0001) was already defined on line 1",
    );
    assert_eq!(
        problem("coil 0 = 1 2").problem,
        MapProblem::BadBit { text: "2".into() }
    );
    assert_eq!(
        problem("input 0 = 70000").problem,
        MapProblem::TooLarge {
            what: "register value",
            value: 70000,
            max: 65535
        }
    );
    assert_eq!(
        problem("input 0x1G = 1").problem,
        MapProblem::BadNumber {
            text: "0x1G".into(),
            what: "address"
        }
    );
    assert_eq!(
        problem("holding 0xFFFF = 1 2").problem,
        MapProblem::PastLastAddress {
            address: 0xFFFF,
            count: 2
        }
    );
    assert_eq!(
        problem("holding 5..=4").problem,
        MapProblem::EmptyRange { first: 5, last: 4 }
    );
    says(
        "holding 5 1 2",
        "line 1: expected `=` and values, or a range `FIRST..=LAST`, found `1`",
    );
    says(
        "holding 5 =",
        "line 1: expected values after `=`, found end of line",
    );
    assert!(matches!(problem("unit 0").problem, MapProblem::UnitId(_)));
    assert_eq!(
        problem("unit 300").problem,
        MapProblem::TooLarge {
            what: "unit number",
            value: 300,
            max: 255
        }
    );
    assert_eq!(problem("\n\nunit 5 6").line, 3);
}

#[test]
fn typed_values_fill_their_registers_in_their_order() {
    let map = SlaveMap::parse(
        "holding 0x0100 float32 CDAB = 229.7 -2\n\
         input 0x200 INT32 = -2   # order ABCD by default\n\
         holding 0x300 string:4 = \"PUMP #7\"  # a '#' in quotes is text\n\
         holding 0x310 string:2 = AB\n\
         input 0 uint64 dcba = 0x0102030405060708\n\
         holding 0x400 = 1\n",
    )
    .expect("a good map");
    let holding = |a| map.get(Table::HoldingRegisters, a);
    let input = |a| map.get(Table::InputRegisters, a);
    // 229.7 = 0x4365B333, words swapped; -2.0 = 0xC0000000.
    assert_eq!(holding(0x100), Some(0xB333));
    assert_eq!(holding(0x101), Some(0x4365));
    assert_eq!(holding(0x102), Some(0x0000));
    assert_eq!(holding(0x103), Some(0xC000));
    assert_eq!(holding(0x104), None);
    assert_eq!(input(0x200), Some(0xFFFF));
    assert_eq!(input(0x201), Some(0xFFFE));
    assert_eq!(
        (0x300..0x304).map(holding).collect::<Vec<_>>(),
        [Some(0x5055), Some(0x4D50), Some(0x2023), Some(0x3700)]
    );
    assert_eq!(holding(0x310), Some(0x4142));
    assert_eq!(holding(0x311), Some(0));
    assert_eq!(
        (0..4).map(input).collect::<Vec<_>>(),
        [Some(0x0807), Some(0x0605), Some(0x0403), Some(0x0201)]
    );
    assert_eq!(holding(0x400), Some(1));
}

#[test]
fn typed_values_that_do_not_fit_are_refused_naming_value_and_type() {
    says(
        "holding 0 int16 = 40000",
        "line 1: 40000 does not fit int16 (-32768 to 32767)",
    );
    assert!(
        problem("holding 0 flaot32 = 1")
            .to_string()
            .contains("`flaot32` is not a data type: choose one of int16")
    );
    assert!(
        problem("holding 0 float32 ACBD = 1")
            .to_string()
            .contains("choose one of ABCD, CDAB, BADC, DCBA")
    );
    assert!(matches!(
        problem("coil 0 float32 = 1").problem,
        MapProblem::TypeOnBits { .. }
    ));
    assert!(matches!(
        problem("holding 0 bit:3 = 1").problem,
        MapProblem::BitValue { .. }
    ));
    assert!(
        problem("holding 0 string:1 = ABC")
            .to_string()
            .contains("holds at most 2")
    );
    says(
        "holding 0 float32 CDAB",
        "line 1: expected `=` and values, found end of line",
    );
    says(
        "holding 0 float32 =",
        "line 1: expected values after `=`, found end of line",
    );
    assert_eq!(
        problem("holding 0 = 1\nholding 0xFFFF float32 = 1").problem,
        MapProblem::PastLastAddress {
            address: 0xFFFF,
            count: 2
        }
    );
    assert!(matches!(
        problem("holding 0 = 1\nholding 0 int32 = 1").problem,
        MapProblem::Duplicate { .. }
    ));
}

#[test]
fn jbus_unit_numbers_are_allowed_in_a_map() {
    assert_eq!(
        SlaveMap::parse("unit 0xFF").map(|m| m.unit().get()),
        Ok(255)
    );
}
