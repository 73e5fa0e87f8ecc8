use super::*;

#[test]
fn addresses_parse_as_one_several_or_dollar() {
    let a = |n| Target::Address(Address::new(n).unwrap());
    assert_eq!(parse_targets("3").unwrap(), [a(3)]);
    assert_eq!(parse_targets("0, 1,2").unwrap(), [a(0), a(1), a(2)]);
    assert_eq!(parse_targets("$").unwrap(), [Target::Assign]);
    assert!(parse_targets("8").is_err());
    assert!(parse_targets("1,1").is_err());
    assert!(parse_targets("x").is_err());
}

#[test]
fn text_messages_get_their_lf_once() {
    assert_eq!(
        text_bytes(&["%051Q990".into(), "%051Q990\\n".into()]),
        b"%051Q990\n%051Q990\n"
    );
}
