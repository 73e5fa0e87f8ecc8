use super::*;

#[test]
fn factory_theoretical_values_follow_the_band_design() {
    let memory = Memory::factory();
    let raw = |i| memory.get(Table::Service, i).get();
    assert_eq!(raw(service::THEORETICAL_CURRENT), 40);
    assert_eq!(raw(service::THEORETICAL_RESISTANCE), 25);
    assert_eq!(raw(service::THEORETICAL_VOLTAGE), 10);
    assert_eq!(raw(service::THEORETICAL_POWER), 40);
}

#[test]
fn factory_values_are_within_every_item_range() {
    let memory = Memory::factory();
    for table in [Table::Machine, Table::Settings, Table::Service] {
        for (item, raw) in table.items().iter().zip(memory.table(table)) {
            assert!(item.accepts(*raw), "{table} {} = {raw}", item.name());
        }
    }
}

#[test]
fn absurd_twin_durations_do_not_overflow_the_clock() {
    let t0 = Instant::now();
    let config = RegulatorConfig {
        seal_period: Some(Duration::MAX),
        measurement: Duration::MAX,
        cooling: Duration::MAX,
        ..RegulatorConfig::default()
    };
    let mut regulator = Regulator::new(Address::new(0).expect("valid"), config, t0);
    assert_eq!(
        regulator.status(t0 + Duration::from_secs(10)).phase,
        Phase::PreHeating
    );
    regulator.start_balancing(t0 + Duration::from_secs(10));
    assert_eq!(
        regulator.status(t0 + Duration::from_secs(20)).phase,
        Phase::PreHeating
    );
}

#[test]
fn model_time_never_runs_backwards() {
    let t0 = Instant::now();
    let mut regulator = Regulator::new(
        Address::new(0).expect("valid"),
        RegulatorConfig::default(),
        t0,
    );
    let later = regulator
        .status(t0 + Duration::from_millis(200))
        .band_temperature;
    let earlier = regulator
        .status(t0 + Duration::from_millis(100))
        .band_temperature;
    assert_eq!(later, earlier);
    assert!(later > 20.0);
}
