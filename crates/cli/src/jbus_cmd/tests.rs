use super::*;

#[test]
fn the_argument_definitions_are_consistent() {
    use clap::Args as _;
    for command in [
        ModbusArgs::augment_args(clap::Command::new("modbus")),
        CrossArgs::augment_args(clap::Command::new("cross")),
        SimCrossArgs::augment_args(clap::Command::new("sim-cross")),
        SimModbusArgs::augment_args(clap::Command::new("sim-modbus")),
    ] {
        command.debug_assert();
    }
}

#[test]
fn addresses_are_decimal_or_hex() {
    assert_eq!(parse_address("70"), Ok(70));
    assert_eq!(parse_address("0x46"), Ok(70));
    assert_eq!(parse_address("0X0046"), Ok(70));
    assert!(parse_address("65536").is_err());
    assert!(parse_address("0xG").unwrap_err().contains("\"0xG\""));
}

#[test]
fn register_values_take_negative_numbers_as_twos_complement() {
    assert_eq!(parse_word("-1"), Ok(0xFFFF));
    assert_eq!(parse_word("-32768"), Ok(0x8000));
    assert!(parse_word("-32769").is_err());
    assert_eq!(parse_word("0xBEEF"), Ok(0xBEEF));
}

#[test]
fn unit_ranges_are_first_to_last_within_1_to_255() {
    assert_eq!(parse_units("1-247"), Ok(1..=247));
    assert_eq!(parse_units("5"), Ok(5..=5));
    assert_eq!(parse_units("200-255"), Ok(200..=255));
    for bad in ["0-3", "9-2", "1-256", "a-b", ""] {
        assert!(parse_units(bad).is_err(), "{bad}");
    }
}

#[test]
fn coil_states_are_on_or_off() {
    assert_eq!(parse_on_off("ON"), Ok(true));
    assert_eq!(parse_on_off("off"), Ok(false));
    assert!(parse_on_off("maybe").is_err());
    assert_eq!(parse_bit_value("1"), Ok(true));
    assert!(parse_bit_value("2").is_err());
}
