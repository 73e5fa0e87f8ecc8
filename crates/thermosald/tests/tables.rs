//! The data tables: names, scaling, ranges, lookups and refusals.

use proptest::prelude::*;
use proptest::sample::select;
use thermosald::frame::{MAX_DATA_ITEMS, RawValue};
use thermosald::request::{Read, Request, RequestError, Write};
use thermosald::tables::{
    Item, LookupError, Scale, Table, Unit, ValueError, machine, runtime, service, settings,
};

fn raw(v: u16) -> RawValue {
    RawValue::new(v).expect("three digits")
}

#[test]
fn tables_have_the_spec_item_counts() {
    assert_eq!(Table::Machine.items().len(), 25);
    assert_eq!(Table::Settings.items().len(), 16);
    assert_eq!(Table::Runtime.items().len(), 7);
    assert_eq!(Table::Service.items().len(), 17);
    for table in Table::ALL {
        assert_eq!(table.items().len(), table.len());
        assert!(
            table.len() <= MAX_DATA_ITEMS,
            "a whole {table} table must fit one message"
        );
        for (i, item) in table.items().iter().enumerate() {
            assert_eq!(usize::from(item.index()), i, "{table} item {}", item.name());
            assert_eq!(item.table(), table);
            assert!(item.raw_min() <= item.raw_max() && item.raw_max() <= 999);
        }
    }
}

#[test]
fn item_names_are_unique_within_a_table() {
    for table in Table::ALL {
        for item in table.items() {
            assert_eq!(
                table.find(item.name()),
                Ok(item),
                "{table} {:?}",
                item.name()
            );
        }
    }
}

#[test]
fn scaling_follows_the_spec_brackets() {
    for (table, index, scale) in [
        // [xx.x]
        (Table::Machine, machine::KINT_GAIN, Scale::Tenths),
        (Table::Machine, machine::MAXIMUM_SEALING_TIME, Scale::Tenths),
        (Table::Runtime, runtime::MAXIMUM_CURRENT, Scale::Tenths),
        (Table::Service, service::WIDTH, Scale::Tenths),
        (Table::Service, service::DUTY_CYCLE, Scale::Tenths),
        // [x.xx]
        (Table::Runtime, runtime::RESISTANCE, Scale::Hundredths),
        (Table::Service, service::THICKNESS, Scale::Hundredths),
        (
            Table::Service,
            service::THEORETICAL_RESISTANCE,
            Scale::Hundredths,
        ),
        (Table::Service, service::SET_RESISTANCE, Scale::Hundredths),
        // [xxx0]
        (Table::Runtime, runtime::POWER, Scale::Tens),
        (Table::Service, service::THEORETICAL_POWER, Scale::Tens),
        (Table::Service, service::SET_POWER, Scale::Tens),
        // Labels (x100) and (x 1000) over [xxx].
        (Table::Settings, settings::HEATING_FACTOR, Scale::Hundredths),
        (Table::Service, service::RESISTIVITY, Scale::Thousandths),
    ] {
        let item = table.item(index).expect("exists");
        assert_eq!(item.scale(), scale, "{table} item {index}");
    }
}

#[test]
fn a_user_writes_sealing_temperature_180_degrees() {
    let item = Table::Settings
        .find("sealing temperature")
        .expect("alias of item 15");
    assert_eq!(item.index(), 15);
    assert_eq!(item.unit(), Unit::Celsius);
    assert_eq!(item.to_raw(180.0), Ok(raw(180)));
    assert_eq!(item.reading(raw(180)).to_string(), "180 °C");
}

#[test]
fn a_user_writes_kint_gain_12_5() {
    let item = Table::Machine.find("KINT gain").expect("item 3");
    assert_eq!(item.to_raw(12.5), Ok(raw(125)));
    assert_eq!(item.from_raw(raw(125)), 12.5);
    assert_eq!(item.reading(raw(125)).to_string(), "12.5");
}

#[test]
fn scaled_values_display_with_their_decimals_and_units() {
    let r = |t: Table, i: u8, v: u16| t.item(i).expect("exists").reading(raw(v)).to_string();
    assert_eq!(r(Table::Runtime, runtime::RESISTANCE, 29), "0.29 Ω");
    assert_eq!(r(Table::Runtime, runtime::MAXIMUM_CURRENT, 375), "37.5 A");
    assert_eq!(r(Table::Runtime, runtime::POWER, 34), "340 VA");
    assert_eq!(
        r(Table::Service, service::RESISTIVITY, 500),
        "0.500 Ω·mm²/m"
    );
    assert_eq!(r(Table::Machine, machine::HEATING_RAMP, 2), "2 °C/10 ms");
}

#[test]
fn names_are_found_whatever_the_case_spaces_and_underscores() {
    let sealing = Table::Settings
        .item(settings::SEALING_TEMPERATURE)
        .expect("exists");
    for name in [
        "Set sealing temperature",
        "set_sealing_temperature",
        "SETSEALINGTEMPERATURE",
        "Set sealing temp. (℃)",
    ] {
        assert_eq!(Table::Settings.find(name), Ok(sealing), "{name}");
    }
    assert_eq!(Table::Settings.lookup("15"), Ok(sealing));
    assert_eq!(
        Table::Runtime.find("temperature").map(Item::index),
        Ok(runtime::TEMPERATURE)
    );
    assert_eq!(
        Table::Machine.find("heat_sealer_address").map(Item::index),
        Ok(machine::ADDRESS)
    );
}

#[test]
fn unknown_and_ambiguous_names_are_refused_with_the_facts() {
    assert_eq!(
        Table::Settings.find("colour"),
        Err(LookupError::NoName {
            table: Table::Settings,
            name: "colour".into()
        })
    );
    assert!(matches!(
        Table::Settings.find("internal data item"),
        Err(LookupError::Ambiguous { ref indexes, .. }) if indexes == &[0, 1, 2, 3, 4, 6, 7, 8, 9]
    ));
    assert_eq!(
        Table::Runtime.item(7),
        Err(LookupError::NoIndex {
            table: Table::Runtime,
            index: 7,
            len: 7
        })
    );
    assert_eq!(
        Table::Runtime.lookup("300"),
        Err(LookupError::NoIndex {
            table: Table::Runtime,
            index: 300,
            len: 7
        })
    );
    assert_eq!("Run-Time".parse::<Table>(), Ok(Table::Runtime));
    assert_eq!("start-up".parse::<Table>(), Ok(Table::Service));
    assert!("recipes".parse::<Table>().is_err());
}

#[test]
fn values_beyond_three_digits_are_refused_naming_item_range_and_unit() {
    let item = Table::Settings
        .find("set sealing temperature")
        .expect("exists");
    let error = item.to_raw(1200.0).expect_err("four digits");
    assert_eq!(
        error,
        ValueError::OutOfRange {
            table: Table::Settings,
            item: "Set sealing temperature",
            value: 1200.0,
            min: 0.0,
            max: 999.0,
            unit: Unit::Celsius
        }
    );
    assert_eq!(
        error.to_string(),
        "settings item \"Set sealing temperature\" = 1200 °C is outside its range, 0 °C to 999 °C"
    );
    assert!(matches!(
        item.to_raw(-1.0),
        Err(ValueError::OutOfRange { .. })
    ));
    let kint = Table::Machine.find("KINT gain").expect("exists");
    assert!(matches!(
        kint.to_raw(100.0),
        Err(ValueError::OutOfRange { max: 99.9, .. })
    ));
}

#[test]
fn values_outside_an_items_own_range_are_refused() {
    let address = Table::Machine.find("heat-sealer address").expect("exists");
    assert!(matches!(
        address.to_raw(8.0),
        Err(ValueError::OutOfRange {
            min: 0.0,
            max: 7.0,
            ..
        })
    ));
    let hz = Table::Machine.find("mains frequency").expect("exists");
    assert_eq!(hz.to_raw(60.0), Ok(raw(60)));
    assert!(hz.to_raw(400.0).is_err());
    let serial = Table::Machine.find("serial enabling").expect("exists");
    assert!(serial.to_raw(2.0).is_err());
}

#[test]
fn values_between_scale_steps_are_refused() {
    let kint = Table::Machine.find("KINT gain").expect("exists");
    assert!(matches!(
        kint.to_raw(12.55),
        Err(ValueError::NotAStep { step: 0.1, .. })
    ));
    let power = Table::Service.find("set power").expect("exists");
    assert_eq!(power.to_raw(450.0), Ok(raw(45)));
    assert!(matches!(
        power.to_raw(455.0),
        Err(ValueError::NotAStep { step: 10.0, .. })
    ));
    let sealing = Table::Settings.find("sealing temperature").expect("exists");
    assert!(matches!(
        sealing.to_raw(180.5),
        Err(ValueError::NotAStep { .. })
    ));
    assert!(matches!(
        sealing.to_raw(f64::NAN),
        Err(ValueError::NotANumber { .. })
    ));
    // Decimal fractions that binary floating point cannot hold exactly still fit.
    let thickness = Table::Service
        .find("sealing plate thickness")
        .expect("exists");
    assert_eq!(thickness.to_raw(0.29), Ok(raw(29)));
}

#[test]
fn run_time_data_cannot_be_written() {
    let temperature = Table::Runtime.find("current temperature").expect("exists");
    assert!(!temperature.writable());
    assert_eq!(
        Write::value(temperature, 100.0),
        Err(RequestError::ReadOnlyTable {
            table: Table::Runtime
        })
    );
    assert_eq!(
        Write::whole(Table::Runtime, vec![RawValue::ZERO; 7]),
        Err(RequestError::ReadOnlyTable {
            table: Table::Runtime
        })
    );
    assert!(Table::Runtime.items().iter().all(|i| !i.writable()));
    assert_eq!(Table::Runtime.write_message(), None);
}

#[test]
fn computed_and_internal_items_are_refused_for_writing() {
    let theoretical = Table::Service.find("theoretical voltage").expect("exists");
    assert_eq!(
        Write::value(theoretical, 12.0),
        Err(RequestError::ReadOnlyItem {
            table: Table::Service,
            item: "Theoretical voltage",
            index: 11
        })
    );
    let internal = Table::Settings.item(0).expect("exists");
    assert!(matches!(
        Write::item(internal, RawValue::ZERO),
        Err(RequestError::ReadOnlyItem { .. })
    ));
}

#[test]
fn whole_table_writes_need_one_value_per_item_in_range() {
    assert!(matches!(
        Write::whole(Table::Settings, vec![RawValue::ZERO; 15]),
        Err(RequestError::ItemCount {
            expected: 16,
            actual: 15,
            ..
        })
    ));
    let mut machine: Vec<RawValue> = Table::Machine
        .items()
        .iter()
        .map(|i| raw(i.raw_min()))
        .collect();
    assert!(Write::whole(Table::Machine, machine.clone()).is_ok());
    machine[usize::from(machine::ADDRESS)] = raw(9);
    assert!(matches!(
        Write::whole(Table::Machine, machine),
        Err(RequestError::RawOutOfRange {
            raw: 9,
            min: 0,
            max: 7,
            ..
        })
    ));
    // Read-only items may hold anything: the regulator keeps its own values.
    let mut service = vec![raw(1); 17];
    service[usize::from(service::THEORETICAL_POWER)] = raw(999);
    assert!(Write::whole(Table::Service, service).is_ok());
}

#[test]
fn reads_of_items_beyond_a_table_are_refused() {
    assert!(matches!(
        Read::index(Table::Settings, 16),
        Err(RequestError::Lookup(LookupError::NoIndex { .. }))
    ));
    assert_eq!(
        Request::Read(Read::index(Table::Runtime, 2).expect("exists"))
            .message()
            .number()
            .get(),
        53
    );
}

proptest! {
    #[test]
    fn every_raw_value_of_every_item_round_trips_through_its_scale(
        item in select(Table::ALL.iter().flat_map(|t| t.items()).collect::<Vec<_>>()),
        pick in any::<prop::sample::Index>(),
    ) {
        let span = usize::from(item.raw_max() - item.raw_min()) + 1;
        let raw = RawValue::new(item.raw_min() + pick.index(span) as u16).expect("in range");
        let value = item.from_raw(raw);
        prop_assert_eq!(item.to_raw(value), Ok(raw));
        // The displayed text parses back to the same value.
        let text = item.reading(raw).to_string();
        let number: f64 = text.split(' ').next().expect("a number first").parse().expect("a number");
        prop_assert_eq!(item.to_raw(number), Ok(raw));
    }
}
