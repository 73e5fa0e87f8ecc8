use super::*;

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

/// The warning `cellbus modbus ARGS…` gives about its address, if any.
fn warning_for(args: &[&str]) -> Option<String> {
    use clap::Parser;
    #[derive(Parser)]
    struct Modbus {
        #[command(subcommand)]
        action: ModbusAction,
    }
    let parsed = Modbus::try_parse_from(std::iter::once("modbus").chain(args.iter().copied()))
        .expect("valid arguments");
    modicon_warning(&parsed.action)
}

#[test]
fn a_register_address_that_looks_like_a_modicon_number_is_warned_about_naming_the_protocol_address()
{
    assert_eq!(
        warning_for(&["read-holding", "40001", "2"]).as_deref(),
        Some(
            "40001 looks like Modicon holding register 40001, which is protocol address 0 of \
             the holding registers; addresses here are 0-based protocol addresses, so this \
             reads address 40001 as asked"
        )
    );
    let input = warning_for(&["read-input", "30011", "1"]).expect("a warning");
    assert!(
        input.contains("input register 30011, which is protocol address 10 "),
        "{input}"
    );
    let write = warning_for(&["write-register", "40100", "7"]).expect("a warning");
    assert!(
        write.contains("protocol address 99 of the holding registers"),
        "{write}"
    );
    assert!(write.contains("writes address 40100 as asked"), "{write}");
}

#[test]
fn coil_numbers_are_only_taken_for_modicon_ones_when_written_with_five_digits() {
    let coil = warning_for(&["read-coils", "00017", "1"]).expect("a warning");
    assert!(
        coil.starts_with(
            "00017 looks like Modicon coil 00017, which is protocol address 16 of the coils"
        ),
        "{coil}"
    );
    assert_eq!(warning_for(&["read-coils", "17", "1"]), None);
    let discrete = warning_for(&["read-discrete", "10001", "8"]).expect("a warning");
    assert!(
        discrete.contains("protocol address 0 of the discrete inputs"),
        "{discrete}"
    );
}

#[test]
fn ordinary_addresses_get_no_warning() {
    for args in [
        ["read-holding", "0", "1"],
        ["read-holding", "0x9C41", "1"],
        ["read-holding", "10001", "1"],
        ["read-input", "50000", "1"],
        ["read-coils", "30001", "1"],
    ] {
        assert_eq!(warning_for(&args), None, "{args:?}");
    }
}
