use super::*;

fn ty(text: &str) -> DataType {
    text.parse().expect("a type")
}

fn encode(data_type: &str, order: Order, value: TypedValue) -> Vec<u16> {
    ty(data_type).encode(order, &value).expect("fits")
}

fn decode(data_type: &str, order: Order, registers: &[u16]) -> TypedValue {
    ty(data_type).decode(order, registers).expect("decodes")
}

/// `value` of `data_type` is encoded as the words of each order in `cases`, and those
/// words decode back to it.
fn assert_words_in_each_order<const N: usize>(
    data_type: &str,
    value: TypedValue,
    cases: [(Order, [u16; N]); 4],
) {
    for (order, words) in cases {
        assert_eq!(encode(data_type, order, value.clone()), words, "{order}");
        assert_eq!(decode(data_type, order, &words), value, "{order}");
    }
}

use Order::{Abcd, Badc, Cdab, Dcba};

#[test]
fn numbers_are_shown_plainly_and_with_an_exponent_only_when_very_small_or_large() {
    let shown = |x: f64| TypedValue::Float(x).to_string();
    assert_eq!(shown(229.7), "229.7");
    assert_eq!(shown(-0.5), "-0.5");
    assert_eq!(shown(0.0), "0");
    assert_eq!(shown(1e-45), "1e-45");
    assert_eq!(shown(3.4028235e38), "3.4028235e38");
    assert_eq!(shown(123_456_789.0), "123456789");
    assert_eq!(shown(f64::NAN), "NaN");
}

#[test]
fn float32_229_7_is_0x4365b333_in_each_order() {
    let cases = [
        (Abcd, [0x4365, 0xB333]),
        (Cdab, [0xB333, 0x4365]),
        (Badc, [0x6543, 0x33B3]),
        (Dcba, [0x33B3, 0x6543]),
    ];
    assert_words_in_each_order("float32", TypedValue::Float(229.7), cases);
}

#[test]
fn int32_minus_2_is_0xfffffffe_in_each_order() {
    let cases = [
        (Abcd, [0xFFFF, 0xFFFE]),
        (Cdab, [0xFFFE, 0xFFFF]),
        (Badc, [0xFFFF, 0xFEFF]),
        (Dcba, [0xFEFF, 0xFFFF]),
    ];
    assert_words_in_each_order("int32", TypedValue::Int(-2), cases);
}

#[test]
fn uint32_0x12345678_in_each_order() {
    let cases = [
        (Abcd, [0x1234, 0x5678]),
        (Cdab, [0x5678, 0x1234]),
        (Badc, [0x3412, 0x7856]),
        (Dcba, [0x7856, 0x3412]),
    ];
    assert_words_in_each_order("uint32", TypedValue::Uint(0x1234_5678), cases);
}

#[test]
fn uint64_0x0102030405060708_reverses_all_four_words_for_cdab() {
    let cases = [
        (Abcd, [0x0102, 0x0304, 0x0506, 0x0708]),
        (Cdab, [0x0708, 0x0506, 0x0304, 0x0102]),
        (Badc, [0x0201, 0x0403, 0x0605, 0x0807]),
        (Dcba, [0x0807, 0x0605, 0x0403, 0x0201]),
    ];
    assert_words_in_each_order("uint64", TypedValue::Uint(0x0102_0304_0506_0708), cases);
}

#[test]
fn int64_minus_1_and_min_in_each_order() {
    for order in Order::ALL {
        assert_eq!(encode("int64", order, TypedValue::Int(-1)), [0xFFFF; 4]);
    }
    assert_eq!(
        encode("int64", Abcd, TypedValue::Int(i64::MIN)),
        [0x8000, 0, 0, 0]
    );
    assert_eq!(
        encode("int64", Dcba, TypedValue::Int(i64::MIN)),
        [0, 0, 0, 0x0080]
    );
    assert_eq!(
        decode("int64", Cdab, &[0, 0, 0, 0x8000]),
        TypedValue::Int(i64::MIN)
    );
}

#[test]
fn float64_1_5_is_0x3ff8000000000000_in_each_order() {
    let cases = [
        (Abcd, [0x3FF8, 0, 0, 0]),
        (Cdab, [0, 0, 0, 0x3FF8]),
        (Badc, [0xF83F, 0, 0, 0]),
        (Dcba, [0, 0, 0, 0xF83F]),
    ];
    for (order, words) in cases {
        assert_eq!(encode("float64", order, TypedValue::Float(1.5)), words);
        assert_eq!(decode("float64", order, &words), TypedValue::Float(1.5));
    }
    // pi = 0x400921FB54442D18.
    assert_eq!(
        encode("float64", Abcd, TypedValue::Float(std::f64::consts::PI)),
        [0x4009, 0x21FB, 0x5444, 0x2D18]
    );
    assert_eq!(
        encode("float64", Cdab, TypedValue::Float(std::f64::consts::PI)),
        [0x2D18, 0x5444, 0x21FB, 0x4009]
    );
}

#[test]
fn sixteen_bit_types_only_swap_bytes() {
    assert_eq!(encode("int16", Abcd, TypedValue::Int(-2)), [0xFFFE]);
    assert_eq!(encode("int16", Cdab, TypedValue::Int(-2)), [0xFFFE]);
    assert_eq!(encode("int16", Badc, TypedValue::Int(-2)), [0xFEFF]);
    assert_eq!(encode("int16", Dcba, TypedValue::Int(-2)), [0xFEFF]);
    assert_eq!(decode("uint16", Abcd, &[0x1234]), TypedValue::Uint(0x1234));
    assert_eq!(decode("uint16", Cdab, &[0x1234]), TypedValue::Uint(0x1234));
    assert_eq!(decode("uint16", Badc, &[0x1234]), TypedValue::Uint(0x3412));
    assert_eq!(decode("uint16", Dcba, &[0x1234]), TypedValue::Uint(0x3412));
    assert_eq!(decode("int16", Abcd, &[0x8000]), TypedValue::Int(-32768));
}

#[test]
fn strings_put_the_first_character_high_and_are_trimmed_of_nul_and_spaces() {
    // "Hi!" in 3 registers: 'H' 'i' | '!' NUL | NUL NUL.
    assert_eq!(
        encode("string:3", Abcd, TypedValue::Text("Hi!".into())),
        [0x4869, 0x2100, 0x0000]
    );
    assert_eq!(
        encode("string:3", Cdab, TypedValue::Text("Hi!".into())),
        [0x4869, 0x2100, 0x0000],
        "a string's registers stay in address order"
    );
    assert_eq!(
        encode("string:3", Badc, TypedValue::Text("Hi!".into())),
        [0x6948, 0x0021, 0x0000]
    );
    assert_eq!(
        encode("string:3", Dcba, TypedValue::Text("Hi!".into())),
        [0x6948, 0x0021, 0x0000]
    );
    // "AB  " then NUL and garbage after it.
    assert_eq!(
        decode("string:4", Abcd, &[0x4142, 0x2020, 0x0058, 0x5959]),
        TypedValue::Text("AB".into())
    );
    assert_eq!(
        decode("string:2", Badc, &[0x4241, 0x2043]),
        TypedValue::Text("ABC".into()),
        "BADC: 'A' is the first register's low byte, the trailing space is dropped"
    );
}

#[test]
fn a_string_with_a_space_inside_keeps_it() {
    assert_eq!(
        decode("string:2", Abcd, &[0x4142, 0x2043]),
        TypedValue::Text("AB C".into())
    );
}

#[test]
fn strings_refuse_too_long_non_ascii_and_numbers() {
    let string2 = ty("string:2");
    assert_eq!(
        string2.encode(Abcd, &TypedValue::Text("ABCDE".into())),
        Err(EncodeError::TooLong {
            text: "ABCDE".into(),
            length: 5,
            data_type: string2,
            max: 4
        })
    );
    assert!(matches!(
        string2.encode(Abcd, &TypedValue::Text("Ä".into())),
        Err(EncodeError::NotAscii {
            character: 'Ä', ..
        })
    ));
    assert!(matches!(
        string2.encode(Abcd, &TypedValue::Int(3)),
        Err(EncodeError::WrongKind { .. })
    ));
    assert_eq!(
        string2.decode(Abcd, &[0x41C3, 0]),
        Err(DecodeError::NotAscii {
            data_type: string2,
            byte: 0xC3,
            position: 1
        })
    );
}

#[test]
fn bits_come_from_the_register_as_read() {
    assert_eq!(decode("bit:0", Abcd, &[0x0001]), TypedValue::Bool(true));
    assert_eq!(decode("bit:15", Abcd, &[0x8000]), TypedValue::Bool(true));
    assert_eq!(decode("bit:15", Dcba, &[0x8000]), TypedValue::Bool(true));
    assert_eq!(decode("bit:3", Abcd, &[0xFFF7]), TypedValue::Bool(false));
    let bit3 = BitIndex::new(3).expect("3");
    assert_eq!(bit3.set(0x00F0, true), 0x00F8);
    assert_eq!(bit3.set(0xFFFF, false), 0xFFF7);
    assert_eq!(
        ty("bit:3").encode(Abcd, &TypedValue::Bool(true)),
        Err(EncodeError::BitNeedsItsRegister { index: bit3 })
    );
}

#[test]
fn integers_refuse_values_out_of_range_or_not_whole_naming_value_and_type() {
    let error = ty("int16")
        .encode(Abcd, &TypedValue::Int(40_000))
        .unwrap_err();
    assert_eq!(
        error.to_string(),
        "40000 does not fit int16 (-32768 to 32767)"
    );
    assert!(ty("uint16").encode(Abcd, &TypedValue::Int(-1)).is_err());
    assert!(
        ty("uint64")
            .encode(Abcd, &TypedValue::Uint(u64::MAX))
            .is_ok()
    );
    assert!(
        ty("int64")
            .encode(Abcd, &TypedValue::Uint(u64::MAX))
            .is_err()
    );
    assert_eq!(
        ty("int32").encode(Abcd, &TypedValue::Float(1.5)),
        Err(EncodeError::NotWhole {
            value: 1.5,
            data_type: DataType::Int32
        })
    );
    assert_eq!(
        encode("int32", Abcd, TypedValue::Float(-2.0)),
        [0xFFFF, 0xFFFE]
    );
    assert!(matches!(
        ty("float32").encode(Abcd, &TypedValue::Float(f64::NAN)),
        Err(EncodeError::NotFinite { .. })
    ));
    assert!(matches!(
        ty("float32").encode(Abcd, &TypedValue::Float(1e39)),
        Err(EncodeError::OutOfRange { .. })
    ));
    assert_eq!(
        ty("float32")
            .encode(Abcd, &TypedValue::Float(1e-50))
            .unwrap_err()
            .to_string(),
        "1e-50 is too small for float32: it would be written as 0 (the smallest number it \
         holds above 0 is about 1.4e-45)"
    );
    assert_eq!(
        encode("float32", Abcd, TypedValue::Float(-0.0)),
        [0x8000, 0]
    );
    assert_eq!(encode("float32", Abcd, TypedValue::Float(1e-45)), [0, 1]);
    assert!(matches!(
        ty("uint16").encode(Abcd, &TypedValue::Text("x".into())),
        Err(EncodeError::WrongKind { .. })
    ));
}

#[test]
fn scaling_multiplies_on_read_and_divides_on_write() {
    let tenths =
        Format::new(DataType::Int16, Abcd).scaled(Scaling::new(0.1, -40.0).expect("usable"));
    // 2297 * 0.1 - 40 = 189.7
    let value = tenths.decode(&[2297]).expect("decodes");
    assert!((value.as_f64().expect("a number") - 189.7).abs() < 1e-9);
    // 22.9 / 0.1 is 228.99999999999997 in binary: within the tolerance of 229.
    let tenths = Format::new(DataType::Uint16, Abcd).scaled(Scaling::new(0.1, 0.0).unwrap());
    assert_eq!(tenths.encode(&TypedValue::Float(22.9)), Ok(vec![229]));
    assert_eq!(tenths.encode_text("229.7"), Ok(vec![2297]));
    assert!(matches!(
        tenths.encode(&TypedValue::Float(22.975)),
        Err(EncodeError::NotWhole { .. })
    ));
    assert_eq!(
        tenths
            .encode(&TypedValue::Float(7000.0))
            .unwrap_err()
            .to_string(),
        "7000 does not fit uint16 (0 to 65535)"
    );
    assert!(Scaling::new(0.0, 1.0).is_err());
    assert!(Scaling::new(1.0, f64::NAN).is_err());
    assert_eq!(
        Format::default().decode(&[7]),
        Ok(TypedValue::Uint(7)),
        "integers stay integers without a scale"
    );
}

#[test]
fn type_and_order_names_parse_in_any_case_and_errors_list_the_choices() {
    assert_eq!(ty("FLOAT32"), DataType::Float32);
    assert_eq!(ty("String:10").registers(), 10);
    assert_eq!(ty("bit:15"), DataType::Bit(BitIndex::new(15).unwrap()));
    assert_eq!("cdab".parse(), Ok(Cdab));
    let error = "float".parse::<DataType>().unwrap_err().to_string();
    assert!(
        error.contains("`float`") && error.contains("float32") && error.contains("bit:N"),
        "{error}"
    );
    let error = "ACBD".parse::<Order>().unwrap_err().to_string();
    assert_eq!(
        error,
        "`ACBD` is not a byte order: choose one of ABCD, CDAB, BADC, DCBA"
    );
    assert!("string".parse::<DataType>().is_err());
    assert!("string:0".parse::<DataType>().is_err());
    assert!("string:126".parse::<DataType>().is_err());
    assert!("bit:16".parse::<DataType>().is_err());
    assert!("int16:2".parse::<DataType>().is_err());
    for name in ["int16", "uint64", "float64", "string:7", "bit:2"] {
        assert_eq!(ty(name).to_string(), name);
    }
}

#[test]
fn registers_per_type() {
    let counts = [
        ("int16", 1),
        ("uint16", 1),
        ("int32", 2),
        ("uint32", 2),
        ("float32", 2),
        ("int64", 4),
        ("uint64", 4),
        ("float64", 4),
        ("string:5", 5),
        ("bit:4", 1),
    ];
    for (name, registers) in counts {
        assert_eq!(ty(name).registers(), registers, "{name}");
    }
}

#[test]
fn values_parse_from_decimal_hex_and_fractions() {
    assert_eq!(
        DataType::Int32.parse_value("-0x10"),
        Ok(TypedValue::Int(-16))
    );
    assert_eq!(
        DataType::Uint16.parse_value("0xBEEF"),
        Ok(TypedValue::Uint(0xBEEF))
    );
    assert_eq!(
        DataType::Float32.parse_value("229.7"),
        Ok(TypedValue::Float(229.7))
    );
    assert_eq!(
        DataType::Float32.parse_value("-1e3"),
        Ok(TypedValue::Float(-1000.0))
    );
    assert!(DataType::Float64.parse_value("nan").is_err());
    assert!(DataType::Int16.parse_value("twelve").is_err());
    assert_eq!(ty("bit:1").parse_value("on"), Ok(TypedValue::Bool(true)));
}

#[test]
fn decoding_refuses_the_wrong_number_of_registers() {
    assert_eq!(
        DataType::Float32.decode(Abcd, &[1]),
        Err(DecodeError::WrongLength {
            data_type: DataType::Float32,
            expected: 2,
            actual: 1
        })
    );
}
