//! Property tests of `jbus::data`: every type in every order round-trips through its
//! registers.

use jbus::data::{BitIndex, DataType, Format, Order, Scaling, StringRegisters, TypedValue};
use proptest::prelude::*;

fn order() -> impl Strategy<Value = Order> {
    prop::sample::select(Order::ALL.to_vec())
}

/// A type and a value it holds exactly.
fn typed_value() -> impl Strategy<Value = (DataType, TypedValue)> {
    prop_oneof![
        any::<i16>().prop_map(|v| (DataType::Int16, TypedValue::Int(v.into()))),
        any::<u16>().prop_map(|v| (DataType::Uint16, TypedValue::Uint(v.into()))),
        any::<i32>().prop_map(|v| (DataType::Int32, TypedValue::Int(v.into()))),
        any::<u32>().prop_map(|v| (DataType::Uint32, TypedValue::Uint(v.into()))),
        any::<i64>().prop_map(|v| (DataType::Int64, TypedValue::Int(v))),
        any::<u64>().prop_map(|v| (DataType::Uint64, TypedValue::Uint(v))),
        any::<f32>()
            .prop_filter("finite", |v| v.is_finite())
            .prop_map(|v| (DataType::Float32, TypedValue::Float(v.into()))),
        any::<f64>()
            .prop_filter("finite", |v| v.is_finite())
            .prop_map(|v| (DataType::Float64, TypedValue::Float(v))),
        (1u16..=125)
            .prop_flat_map(|registers| {
                let max = 2 * usize::from(registers);
                // ASCII without NUL, not ending in a space (trailing spaces are padding).
                (
                    Just(registers),
                    prop::collection::vec(1u8..=0x7F, 0..=max).prop_map(|mut bytes| {
                        while bytes.last() == Some(&b' ') {
                            bytes.pop();
                        }
                        String::from_utf8(bytes).expect("ASCII")
                    }),
                )
            })
            .prop_map(|(registers, text)| (
                DataType::String(StringRegisters::new(registers).expect("1-125")),
                TypedValue::Text(text)
            )),
    ]
}

proptest! {
    #[test]
    fn every_type_in_every_order_round_trips_through_its_registers(
        (data_type, value) in typed_value(),
        order in order(),
    ) {
        let words = data_type.encode(order, &value).expect("the value fits its type");
        prop_assert_eq!(words.len(), usize::from(data_type.registers()));
        let back = data_type.decode(order, &words).expect("decodes");
        match (&value, &back) {
            // Compare floats by their bits (so -0.0 and 0.0 differ and NaN cannot occur).
            (TypedValue::Float(a), TypedValue::Float(b)) if data_type == DataType::Float32 => {
                prop_assert_eq!((*a as f32).to_bits(), (*b as f32).to_bits());
            }
            (TypedValue::Float(a), TypedValue::Float(b)) => prop_assert_eq!(a.to_bits(), b.to_bits()),
            _ => prop_assert_eq!(&value, &back),
        }
    }

    #[test]
    fn orders_differ_only_as_documented(words in prop::array::uniform4(any::<u16>())) {
        // Decoding the same registers in the four orders is one value with its words
        // reversed and/or its bytes swapped.
        let abcd = DataType::Uint64.decode(Order::Abcd, &words).expect("4 registers");
        let TypedValue::Uint(abcd) = abcd else { panic!("uint64 decodes as Uint") };
        let reversed: Vec<u16> = words.iter().rev().copied().collect();
        let swapped: Vec<u16> = words.iter().map(|w| w.swap_bytes()).collect();
        prop_assert_eq!(DataType::Uint64.decode(Order::Cdab, &reversed), Ok(TypedValue::Uint(abcd)));
        prop_assert_eq!(DataType::Uint64.decode(Order::Badc, &swapped), Ok(TypedValue::Uint(abcd)));
        prop_assert_eq!(DataType::Uint64.decode(Order::Dcba, &words), Ok(TypedValue::Uint(abcd.swap_bytes())));
    }

    #[test]
    fn a_bit_written_through_its_register_reads_back(
        register in any::<u16>(), index in 0u8..16, on in any::<bool>(), order in order(),
    ) {
        let bit = BitIndex::new(index).expect("0-15");
        let written = bit.set(register, on);
        prop_assert_eq!(DataType::Bit(bit).decode(order, &[written]), Ok(TypedValue::Bool(on)));
        prop_assert_eq!(written & !(1 << index), register & !(1 << index), "other bits unchanged");
    }

    #[test]
    fn scaled_integers_round_trip_through_their_registers(
        raw in any::<i32>(),
        scale in prop::sample::select(vec![0.1, 0.01, 0.5, 2.0, 10.0, -1.0]),
        offset in prop::sample::select(vec![0.0, -40.0, 273.15]),
        order in order(),
    ) {
        let format = Format::new(DataType::Int32, order).scaled(Scaling::new(scale, offset).expect("usable"));
        let words = DataType::Int32.encode(order, &TypedValue::Int(raw.into())).expect("fits");
        let value = format.decode(&words).expect("decodes");
        prop_assert_eq!(format.encode(&value), Ok(words));
    }
}
