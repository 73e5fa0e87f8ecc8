use super::*;
use proptest::prelude::*;

/// The layout of the 3.3-9 example, with the values the fact sheet quotes.
const EXAMPLE: &[u8] = b"%HEADER\r\n\
NAME=M000\r\n\
MACHINE=BM\r\n\
START=2003/01/30 08/00/00\r\n\
END=2003/01/30 17/30/00\r\n\
PANASONIC=3010\r\n\
%MANAGEMENT\r\n\
PRODUCTPLAN1=0000010\r\n\
PRODUCTPLAN2=0000000\r\n\
PRODUCT1=0000005\r\n\
%CHARACTER\r\n\
PICKUP_RATE=075.75\r\n\
MOUNT_RATE=099.50\r\n\
PARTS_EXHAUST_C=0000002\r\n\
PICKUP=0001234\r\n\
MOUNT=0001200\r\n\
PICKUP_MISS=0000030\r\n\
RECOG_ERR1=0000004\r\n\
*\r\n";

#[test]
fn production_data_example_parses_into_named_counters_and_rates() {
    let data = ProductionData::parse(EXAMPLE).expect("valid production data");
    assert_eq!(data.header.name.as_deref(), Some("M000"));
    assert_eq!(data.header.machine.as_deref(), Some(MACHINE_BM));
    assert_eq!(data.header.format.as_deref(), Some(PANASONIC_FORMAT));
    assert_eq!(
        data.header.start.map(|t| t.to_string()).as_deref(),
        Some("2003/01/30 08/00/00")
    );
    assert_eq!(data.count(Counter::Product1), Some(5));
    assert_eq!(data.count(Counter::ProductPlan1), Some(10));
    assert_eq!(data.count(Counter::Pickup), Some(1234));
    assert_eq!(data.count(Counter::RecognitionError1), Some(4));
    assert_eq!(data.count(Counter::BoardRecognitionError2), None);
    assert_eq!(
        data.rate(RateKind::Pickup).map(Rate::hundredths),
        Some(7575)
    );
    assert_eq!(
        data.rate(RateKind::Mount).map(|r| r.to_string()).as_deref(),
        Some("099.50")
    );
    assert_eq!(data.to_bytes(), EXAMPLE, "re-encodes byte for byte");
}

#[test]
fn unknown_keys_and_values_are_kept_as_text() {
    let data = ProductionData::parse(
        b"%HEADER\r\nLINE=2\r\n%CHARACTER\r\nCYCLE=12:30\r\nX_RATE=abc\r\n*\r\n",
    )
    .expect("valid layout");
    assert_eq!(
        data.header.other,
        vec![Field {
            key: "LINE".into(),
            value: Value::Count(2)
        }]
    );
    assert_eq!(
        data.value(CHARACTER_SECTION, "CYCLE"),
        Some(&Value::Text("12:30".into()))
    );
    assert_eq!(
        data.value(CHARACTER_SECTION, "X_RATE"),
        Some(&Value::Text("abc".into()))
    );
}

#[test]
fn production_data_parsing_says_what_is_wrong() {
    let headless = [b"%MANAGEMENT\r\n*\r\n".as_slice(), b""].map(ProductionData::parse);
    assert!(
        headless
            .iter()
            .all(|e| matches!(e, Err(ProductionDataError::MissingHeader { .. }))),
        "{headless:?}"
    );
    assert_eq!(
        ProductionData::parse(b"%HEADER\r\nNAME=M\r\n"),
        Err(ProductionDataError::MissingEnd)
    );
    assert_eq!(
        ProductionData::parse(b"%HEADER\r\nNOEQUALS\r\n*\r\n"),
        Err(ProductionDataError::BadLine {
            line: 2,
            text: "NOEQUALS".into()
        })
    );
    assert!(matches!(
        ProductionData::parse(b"%HEADER\r\nSTART=yesterday\r\n*\r\n"),
        Err(ProductionDataError::BadTimestamp { .. })
    ));
    assert_eq!(
        ProductionData::parse(b"%HEADER\r\n*\r\nX=1\r\n"),
        Err(ProductionDataError::TrailingData)
    );
}

#[test]
fn rates_are_hundredths_of_a_percent_up_to_100() {
    assert_eq!(Rate::parse(b"075.75"), Some(Rate(7575)));
    assert_eq!(Rate::parse(b"100.00"), Some(Rate::FULL));
    assert_eq!(Rate::parse(b"5.10"), Some(Rate(510)));
    assert_eq!(Rate::parse(b"100.01"), None);
    assert_eq!(Rate::parse(b"75.7"), None);
    assert_eq!(Rate::parse(b".75"), None);
    assert_eq!(Rate::parse(b"1000.00"), None);
    assert_eq!(
        Rate::from_hundredths(10_001),
        Err(RateError { hundredths: 10_001 })
    );
    assert_eq!(Rate::ratio(3, 4), Rate(7500));
    assert_eq!(Rate::ratio(2, 3), Rate(6667));
    assert_eq!(Rate::ratio(5, 0), Rate(0));
    assert_eq!(Rate::ratio(9, 4), Rate::FULL);
}

#[test]
fn counters_saturate_at_seven_digits() {
    let mut data = ProductionData::default();
    data.set_count(Counter::Pickup, 12_345_678_901);
    assert_eq!(data.count(Counter::Pickup), Some(MAX_COUNT));
}

proptest! {
    #[test]
    fn production_data_round_trips(
        counts in prop::collection::vec(0u64..=u64::from(MAX_COUNT), Counter::ALL.len()),
        rates in prop::collection::vec(0u32..=10_000, 2),
        start in 0u64..2_000_000_000,
        span in 0u64..10_000_000,
    ) {
        let epoch = Timestamp::new(1970, 1, 1, 0, 0, 0).expect("valid");
        let mut data = ProductionData {
            header: ProductionHeader {
                name: Some("M000P".into()),
                machine: Some(MACHINE_BM.into()),
                start: Some(epoch.plus_seconds(start)),
                end: Some(epoch.plus_seconds(start + span)),
                format: Some(PANASONIC_FORMAT.into()),
                other: Vec::new(),
            },
            sections: Vec::new(),
        };
        for (counter, count) in Counter::ALL.into_iter().zip(counts) {
            data.set_count(counter, count);
        }
        for (kind, rate) in RateKind::ALL.into_iter().zip(rates) {
            data.set_rate(kind, Rate::from_hundredths(rate).expect("in range"));
        }
        prop_assert_eq!(ProductionData::parse(&data.to_bytes()), Ok(data));
    }
}
