//! The regulator twin: band physics, faults, calibration, EEPROM; time is always explicit.
//!
//! Factory data: ramp 2 °C/10 ms (200 °C/s), pre-heating 80 °C, sealing 180 °C, one
//! 5.0 × 0.20 × 500 mm band of 0.500 Ω·mm²/m (0.25 Ω at 20 °C), set voltage 10 V, set maximum
//! current 45 A. Default twin: impulses every 3 s of 0.8 s, cooling τ = 0.8 s, 20 °C ambient.

use std::time::{Duration, Instant};

use thermosald::device::band::TCR_PER_K;
use thermosald::device::{Phase, RegulatorBus, RegulatorConfig, Status};
use thermosald::diagnostic::{self, Fault};
use thermosald::exchange::{Classified, Exchange, ExchangeError};
use thermosald::frame::{Address, Frame};
use thermosald::request::Write;
use thermosald::tables::{Table, machine, runtime, service, settings};

use crate::common::{addr, ask, decode_one, send};

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(s)
}

fn line_at_0() -> (RegulatorBus, Instant) {
    let t0 = Instant::now();
    (
        RegulatorBus::new(&[addr(0)], t0).expect("one regulator"),
        t0,
    )
}

fn status(line: &mut RegulatorBus, address: u8, now: Instant) -> Status {
    line.regulator_mut(addr(address))
        .expect("regulator present")
        .status(now)
}

/// Run-time data read over the protocol.
fn runtime_raw(line: &mut RegulatorBus, address: u8, now: Instant) -> Vec<u16> {
    let reply = ask(line, format!("%{address}53Q990\n").as_bytes(), now);
    reply.data().iter().map(|r| r.get()).collect()
}

fn fault(line: &mut RegulatorBus, address: u8, now: Instant) -> u16 {
    runtime_raw(line, address, now)[usize::from(runtime::FAULT)]
}

/// Regulator 0 gets `fault` at `now`.
fn provoke(line: &mut RegulatorBus, fault: Fault, now: Instant) {
    line.regulator_mut(addr(0))
        .expect("present")
        .provoke(fault, now);
}

/// The cause of regulator 0's `fault` is repaired at `now`.
fn repair(line: &mut RegulatorBus, fault: Fault, now: Instant) {
    line.regulator_mut(addr(0))
        .expect("present")
        .remove_cause(fault, now);
}

/// Clear faults (command 14) to regulator 0 at `now`; its echo.
fn clear_faults(line: &mut RegulatorBus, now: Instant) -> Frame {
    ask(line, b"%014Q000000\n", now)
}

fn close(actual: f64, expected: f64) -> bool {
    (actual - expected).abs() < 1e-6
}

#[test]
fn the_band_follows_the_heating_ramp_to_the_pre_heating_temperature() {
    let (mut line, t0) = line_at_0();
    let halfway = status(&mut line, 0, t0 + secs(0.15));
    assert!(close(halfway.band_temperature, 50.0), "{halfway:?}");
    assert_eq!(halfway.phase, Phase::PreHeating);
    assert!(close(
        status(&mut line, 0, t0 + secs(0.3)).band_temperature,
        80.0
    ));
    assert!(close(
        status(&mut line, 0, t0 + secs(2.9)).band_temperature,
        80.0
    ));
}

#[test]
fn a_sealing_impulse_ramps_to_the_sealing_temperature_holds_then_cools() {
    let (mut line, t0) = line_at_0();
    let rising = status(&mut line, 0, t0 + secs(3.25));
    assert_eq!(rising.phase, Phase::Sealing);
    assert!(close(rising.band_temperature, 130.0), "{rising:?}");
    assert!(close(
        status(&mut line, 0, t0 + secs(3.5)).band_temperature,
        180.0
    ));
    let holding = status(&mut line, 0, t0 + secs(3.75));
    assert_eq!(holding.phase, Phase::Sealing);
    assert!(close(holding.band_temperature, 180.0));
    let cooling = status(&mut line, 0, t0 + secs(4.0));
    assert_eq!(cooling.phase, Phase::Cooling);
    assert_eq!(cooling.voltage, 0.0);
    // Newton cooling from 180 °C toward 20 °C with τ = 0.8 s, 0.2 s after the impulse.
    assert!(close(
        cooling.band_temperature,
        20.0 + 160.0 * (-0.25f64).exp()
    ));
    // Back at pre-heating τ·ln(160/60) = 0.785 s after the impulse.
    assert_eq!(status(&mut line, 0, t0 + secs(4.58)).phase, Phase::Cooling);
    let back = status(&mut line, 0, t0 + secs(4.59));
    assert_eq!(back.phase, Phase::PreHeating);
    assert!(close(back.band_temperature, 80.0));
}

#[test]
fn the_measured_temperature_reaches_the_set_point_over_the_line() {
    let (mut line, t0) = line_at_0();
    let during_seal = runtime_raw(&mut line, 0, t0 + secs(3.6));
    assert_eq!(during_seal[usize::from(runtime::TEMPERATURE)], 180);
    let between = runtime_raw(&mut line, 0, t0 + secs(5.0));
    assert_eq!(between[usize::from(runtime::TEMPERATURE)], 80);
}

#[test]
fn seal_cycles_repeat_on_the_configured_period_for_hours() {
    let t0 = Instant::now();
    let config = RegulatorConfig {
        seal_period: Some(Duration::from_secs(2)),
        ..RegulatorConfig::default()
    };
    let mut line = RegulatorBus::with_config(&[addr(0)], config, t0).expect("one regulator");
    for k in 1..=30u32 {
        let start = t0 + Duration::from_secs(2) * k;
        assert_ne!(
            status(&mut line, 0, start - secs(0.1)).phase,
            Phase::Sealing,
            "cycle {k}"
        );
        assert_eq!(
            status(&mut line, 0, start + secs(0.1)).phase,
            Phase::Sealing,
            "cycle {k}"
        );
    }
    // Ten hours of model time later (18 000 cycles), still on the beat.
    let hours = t0 + Duration::from_secs(10 * 3600);
    assert_eq!(
        status(&mut line, 0, hours + secs(0.1)).phase,
        Phase::Sealing
    );
    assert_eq!(
        status(&mut line, 0, hours + secs(1.5)).phase,
        Phase::Cooling
    );
    assert_eq!(
        status(&mut line, 0, hours + secs(1.7)).phase,
        Phase::PreHeating
    );
    assert!(close(
        status(&mut line, 0, hours + secs(1.9)).band_temperature,
        80.0
    ));
}

#[test]
fn without_a_seal_period_the_band_holds_the_pre_heating_temperature() {
    let t0 = Instant::now();
    let config = RegulatorConfig {
        seal_period: None,
        ..RegulatorConfig::default()
    };
    let mut line = RegulatorBus::with_config(&[addr(0)], config, t0).expect("one regulator");
    let later = status(&mut line, 0, t0 + Duration::from_secs(60));
    assert_eq!(later.phase, Phase::PreHeating);
    assert!(close(later.band_temperature, 80.0));
}

#[test]
fn a_steeper_ramp_written_over_the_line_heats_faster() {
    let (mut line, t0) = line_at_0();
    // Machine item 1 = 5 °C per 10 ms: 80 → 180 °C in 0.2 s.
    let echo = ask(&mut line, b"%011Q010005\n", t0 + secs(1.0));
    assert_eq!(echo.to_bytes(), b"%011R010005\n");
    assert!(close(
        status(&mut line, 0, t0 + secs(3.1)).band_temperature,
        130.0
    ));
    assert!(close(
        status(&mut line, 0, t0 + secs(3.2)).band_temperature,
        180.0
    ));
}

#[test]
fn run_time_values_follow_the_band_formulas_and_the_service_data() {
    let (mut line, t0) = line_at_0();
    let service_data = ask(&mut line, b"%058Q990\n", t0 + secs(1.0));
    let value = |index: u8| {
        let item = Table::Service.item(index).expect("exists");
        item.from_raw(service_data.data()[usize::from(index)])
    };
    // R20 = ρ × L / A × series / parallel; U = set voltage.
    let area = value(service::WIDTH) * value(service::THICKNESS);
    let r20 = value(service::RESISTIVITY) * value(service::LENGTH) / 1000.0 / area
        * value(service::IN_SERIES)
        / value(service::IN_PARALLEL);
    assert!(close(r20, 0.25));
    assert!(close(value(service::THEORETICAL_RESISTANCE), r20));
    let u = value(service::SET_VOLTAGE);
    let r_at = |t: f64| r20 * (1.0 + TCR_PER_K * (t - 20.0));

    // Holding 180 °C during the first impulse.
    let hot = runtime_raw(&mut line, 0, t0 + secs(3.6));
    assert_eq!(hot[usize::from(runtime::TEMPERATURE)], 180);
    assert_eq!(hot[usize::from(runtime::FAULT)], diagnostic::NONE);
    assert_eq!(
        hot[usize::from(runtime::RESISTANCE)],
        (r_at(180.0) * 100.0).round() as u16
    );
    assert_eq!(hot[usize::from(runtime::VOLTAGE)], u as u16);
    assert_eq!(
        hot[usize::from(runtime::POWER)],
        (u * u / r_at(180.0) / 10.0).round() as u16
    );
    // The impulse began at 80 °C, where the band's resistance is lowest: the peak current.
    assert_eq!(
        hot[usize::from(runtime::MAXIMUM_CURRENT)],
        (u / r_at(80.0) * 10.0).round() as u16
    );

    // Cooling between impulses: not fired, no voltage, no power.
    let cooling = runtime_raw(&mut line, 0, t0 + secs(4.0));
    assert_eq!(cooling[usize::from(runtime::VOLTAGE)], 0);
    assert_eq!(cooling[usize::from(runtime::POWER)], 0);

    // A longer band: R, theoretical values and power follow the new service data once the
    // regulator is balanced on it (until then it measures the new band against the old one).
    let echo = ask(&mut line, b"%018Q030600\n", t0 + secs(4.5));
    assert_eq!(echo.data()[0].get(), 600);
    let service_data = ask(&mut line, b"%058Q990\n", t0 + secs(5.0));
    assert_eq!(
        service_data.data()[usize::from(service::THEORETICAL_RESISTANCE)].get(),
        30
    );
    ask(&mut line, b"%015Q000000\n", t0 + secs(5.5));
    assert_eq!(fault(&mut line, 0, t0 + secs(12.0)), diagnostic::NONE);
    let r20 = 0.3;
    let hold = status(&mut line, 0, t0 + secs(12.5));
    assert_eq!(hold.phase, Phase::PreHeating);
    // Balancing measured 0.01 °C above 20 °C: that is the calibration's error.
    assert!((hold.band_temperature - 80.0).abs() < 0.05, "{hold:?}");
    assert!(close(
        hold.resistance,
        r20 * (1.0 + TCR_PER_K * (hold.band_temperature - 20.0))
    ));
    assert!(close(hold.current, u / hold.resistance));
    assert!(close(hold.power, u * hold.current));
    let raw = runtime_raw(&mut line, 0, t0 + secs(12.5));
    assert_eq!(
        raw[usize::from(runtime::RESISTANCE)],
        (hold.resistance * 100.0).round() as u16
    );
    assert_eq!(
        raw[usize::from(runtime::POWER)],
        (hold.power / 10.0).round() as u16
    );
}

#[test]
fn an_open_band_is_latched_at_once_and_cleared_only_after_repair() {
    let (mut line, t0) = line_at_0();
    provoke(&mut line, Fault::OpenBand, t0 + secs(1.0));
    let open = runtime_raw(&mut line, 0, t0 + secs(1.0));
    assert_eq!(open[usize::from(runtime::FAULT)], Fault::OpenBand.code());
    assert_eq!(open[usize::from(runtime::RESISTANCE)], 999);
    assert_eq!(open[usize::from(runtime::TEMPERATURE)], 0);
    assert_eq!(open[usize::from(runtime::VOLTAGE)], 0);
    // Clear faults is echoed, but the band is still open.
    assert_eq!(
        clear_faults(&mut line, t0 + secs(1.5)).to_bytes(),
        b"%014R000000\n"
    );
    assert_eq!(fault(&mut line, 0, t0 + secs(2.0)), Fault::OpenBand.code());
    repair(&mut line, Fault::OpenBand, t0 + secs(2.2));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(2.5)),
        Fault::OpenBand.code(),
        "latched until cleared"
    );
    clear_faults(&mut line, t0 + secs(3.0));
    assert_eq!(fault(&mut line, 0, t0 + secs(3.5)), diagnostic::NONE);
    assert_eq!(
        status(&mut line, 0, t0 + secs(3.6)).phase,
        Phase::PreHeating
    );
}

#[test]
fn a_short_circuit_is_latched_and_cleared_after_repair() {
    let (mut line, t0) = line_at_0();
    provoke(&mut line, Fault::ShortCircuit, t0 + secs(1.0));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(1.0)),
        Fault::ShortCircuit.code()
    );
    clear_faults(&mut line, t0 + secs(1.5));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(2.0)),
        Fault::ShortCircuit.code()
    );
    repair(&mut line, Fault::ShortCircuit, t0 + secs(2.2));
    clear_faults(&mut line, t0 + secs(2.5));
    assert_eq!(fault(&mut line, 0, t0 + secs(3.0)), diagnostic::NONE);
}

#[test]
fn over_current_is_latched_while_the_band_is_fired_and_stops_it() {
    let (mut line, t0) = line_at_0();
    provoke(&mut line, Fault::OverCurrent, t0 + secs(1.0));
    let tripped = status(&mut line, 0, t0 + secs(1.0));
    assert_eq!(tripped.phase, Phase::Faulted(Fault::OverCurrent));
    assert_eq!(tripped.voltage, 0.0);
    assert_eq!(
        fault(&mut line, 0, t0 + secs(1.1)),
        Fault::OverCurrent.code()
    );
    clear_faults(&mut line, t0 + secs(1.5));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(2.0)),
        Fault::OverCurrent.code(),
        "the supply is still too high"
    );
    repair(&mut line, Fault::OverCurrent, t0 + secs(2.2));
    clear_faults(&mut line, t0 + secs(2.5));
    assert_eq!(fault(&mut line, 0, t0 + secs(3.0)), diagnostic::NONE);
}

#[test]
fn a_set_maximum_current_below_the_band_current_trips_over_current() {
    let (mut line, t0) = line_at_0();
    // U / R(80 °C) = 10 V / 0.2665 Ω = 37.5 A > 30 A.
    assert_eq!(
        ask(&mut line, b"%018Q130030\n", t0 + secs(1.0)).data()[0].get(),
        30
    );
    assert_eq!(
        fault(&mut line, 0, t0 + secs(1.5)),
        Fault::OverCurrent.code()
    );
    ask(&mut line, b"%018Q130045\n", t0 + secs(2.0));
    clear_faults(&mut line, t0 + secs(2.5));
    assert_eq!(fault(&mut line, 0, t0 + secs(3.0)), diagnostic::NONE);
}

#[test]
fn a_weak_supply_is_found_at_the_end_of_the_next_impulse_as_temperature_not_reached() {
    let (mut line, t0) = line_at_0();
    provoke(&mut line, Fault::TemperatureNotReached, t0 + secs(1.0));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(3.5)),
        diagnostic::NONE,
        "still heating in the impulse"
    );
    // The impulse ends at 3.8 s, at 80 + 0.8 s × 18 °C/s = 94.4 °C.
    let after = status(&mut line, 0, t0 + secs(3.9));
    assert_eq!(after.phase, Phase::Faulted(Fault::TemperatureNotReached));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(4.0)),
        Fault::TemperatureNotReached.code()
    );
    clear_faults(&mut line, t0 + secs(4.5));
    assert_eq!(
        fault(&mut line, 0, t0 + secs(5.0)),
        Fault::TemperatureNotReached.code()
    );
    repair(&mut line, Fault::TemperatureNotReached, t0 + secs(5.2));
    clear_faults(&mut line, t0 + secs(5.5));
    assert_eq!(fault(&mut line, 0, t0 + secs(6.0)), diagnostic::NONE);
    // Cycles restart from the clear: the next impulse at 8.5 s reaches 180 °C again.
    assert!(close(
        status(&mut line, 0, t0 + secs(9.2)).band_temperature,
        180.0
    ));
    assert_eq!(fault(&mut line, 0, t0 + secs(9.5)), diagnostic::NONE);
}

#[test]
fn master_reset_then_address_then_balancing_shows_35_then_36_then_0() {
    let (mut line, t0) = line_at_0();
    let echo = ask(&mut line, b"%099Q000000\n", t0 + secs(10.0));
    assert_eq!(echo.to_bytes(), b"%099R000000\n");
    // No address any more: address 0 is silent.
    assert!(send(&mut line, b"%053Q990\n", t0 + secs(10.5)).is_empty());
    assert_eq!(line.regulators()[0].address(), None);
    // Address assignment through '$'.
    assert_eq!(
        ask(&mut line, b"%$10Q000002\n", t0 + secs(11.0)).to_bytes(),
        b"%$10R000002\n"
    );
    assert_eq!(
        fault(&mut line, 2, t0 + secs(11.5)),
        diagnostic::CALIBRATION_REQUEST
    );
    // Factory data are back.
    let machine_data = ask(&mut line, b"%251Q990\n", t0 + secs(12.0));
    assert_eq!(machine_data.data()[usize::from(machine::ADDRESS)].get(), 2);
    assert_eq!(
        machine_data.data()[usize::from(machine::HEATING_RAMP)].get(),
        2
    );
    // Not calibrated: the band is not fired.
    assert_eq!(
        status(&mut line, 2, t0 + secs(20.0)).phase,
        Phase::Uncalibrated
    );
    assert_eq!(
        fault(&mut line, 2, t0 + secs(20.0)),
        diagnostic::CALIBRATION_REQUEST
    );

    // The band has long cooled to ambient: balancing just measures, 3 s.
    let start = t0 + secs(30.0);
    ask(&mut line, b"%215Q000000\n", start);
    assert_eq!(
        fault(&mut line, 2, start + secs(0.5)),
        diagnostic::CALIBRATION_IN_PROGRESS
    );
    assert_eq!(
        fault(&mut line, 2, start + secs(2.9)),
        diagnostic::CALIBRATION_IN_PROGRESS
    );
    assert_eq!(fault(&mut line, 2, start + secs(3.2)), diagnostic::NONE);
    // Ready to work: pre-heating from ambient.
    let working = status(&mut line, 2, start + secs(3.2));
    assert_eq!(working.phase, Phase::PreHeating);
    assert!(close(
        status(&mut line, 2, start + secs(4.0)).band_temperature,
        80.0
    ));
}

#[test]
fn balancing_a_hot_band_waits_until_it_cools_below_the_gradient() {
    let (mut line, t0) = line_at_0();
    // At 3.6 s the band holds 180 °C. Stable when (T − 20)/τ ≤ 5 °C/10 s, i.e. T − 20 ≤ 0.4:
    // wait τ·ln(160/0.4) = 4.79 s, then measure 3 s.
    let start = t0 + secs(3.6);
    ask(&mut line, b"%015Q000000\n", start);
    let expected = 0.8 * (160.0f64 / 0.4).ln() + 3.0;
    assert_eq!(
        fault(&mut line, 0, start + secs(expected - 0.1)),
        diagnostic::CALIBRATION_IN_PROGRESS
    );
    let regulator = line.regulator_mut(addr(0)).expect("present");
    assert_eq!(
        regulator.fault_number(start + secs(expected - 0.001)),
        diagnostic::CALIBRATION_IN_PROGRESS
    );
    assert_eq!(
        regulator.fault_number(start + secs(expected + 0.001)),
        diagnostic::NONE
    );
    // (Questions 240 ms apart or more: the line's turnaround.)
    assert_eq!(
        fault(&mut line, 0, start + secs(expected + 0.2)),
        diagnostic::NONE
    );
}

#[test]
fn balancing_at_a_wrong_reference_temperature_offsets_the_measurement() {
    let (mut line, t0) = line_at_0();
    ask(&mut line, b"%099Q000000\n", t0);
    ask(&mut line, b"%$10Q000000\n", t0 + secs(1.0));
    // The operator says the band is at 30 °C while it is at 20 °C.
    ask(&mut line, b"%012Q130030\n", t0 + secs(1.5));
    ask(&mut line, b"%015Q000000\n", t0 + secs(2.0));
    let regulated = status(&mut line, 0, t0 + secs(6.0));
    assert_eq!(regulated.phase, Phase::PreHeating);
    let measured = regulated.measured_temperature.expect("band present");
    assert!(close(measured, 80.0), "{regulated:?}");
    assert!(close(regulated.band_temperature, 70.0), "{regulated:?}");
}

#[test]
fn settings_are_volatile_until_saved_to_eeprom() {
    let (mut line, t0) = line_at_0();
    let sealing = |line: &mut RegulatorBus, now| ask(line, b"%052Q150\n", now).data()[0].get();
    ask(&mut line, b"%012Q150150\n", t0 + secs(1.0));
    assert_eq!(sealing(&mut line, t0 + secs(1.5)), 150);
    assert_eq!(
        line.regulators()[0].eeprom(Table::Settings)[usize::from(settings::SEALING_TEMPERATURE)]
            .get(),
        180
    );
    line.power_cycle(t0 + secs(2.0));
    assert_eq!(
        sealing(&mut line, t0 + secs(2.5)),
        180,
        "lost without a save"
    );

    ask(&mut line, b"%012Q150150\n", t0 + secs(3.0));
    ask(&mut line, b"%016Q000000\n", t0 + secs(3.5));
    ask(&mut line, b"%012Q150160\n", t0 + secs(4.0));
    assert_eq!(sealing(&mut line, t0 + secs(4.5)), 160);
    // Load from EEPROM brings back the saved value.
    ask(&mut line, b"%017Q000000\n", t0 + secs(5.0));
    assert_eq!(sealing(&mut line, t0 + secs(5.5)), 150);
    ask(&mut line, b"%012Q150170\n", t0 + secs(6.0));
    line.power_cycle(t0 + secs(6.5));
    assert_eq!(sealing(&mut line, t0 + secs(7.0)), 150);
}

#[test]
fn machine_and_service_writes_are_volatile_too() {
    let (mut line, t0) = line_at_0();
    ask(&mut line, b"%011Q030125\n", t0 + secs(1.0));
    ask(&mut line, b"%018Q150012\n", t0 + secs(1.5));
    line.power_cycle(t0 + secs(2.0));
    assert_eq!(
        ask(&mut line, b"%051Q030\n", t0 + secs(2.5)).data()[0].get(),
        50
    );
    assert_eq!(
        ask(&mut line, b"%058Q150\n", t0 + secs(3.0)).data()[0].get(),
        10
    );
}

#[test]
fn an_unsaved_address_and_calibration_are_lost_at_power_cycle_and_a_saved_one_kept() {
    let (mut line, t0) = line_at_0();
    ask(&mut line, b"%099Q000000\n", t0);
    ask(&mut line, b"%$10Q000004\n", t0 + secs(1.0));
    ask(&mut line, b"%415Q000000\n", t0 + secs(1.5));
    assert_eq!(fault(&mut line, 4, t0 + secs(5.0)), diagnostic::NONE);
    line.power_cycle(t0 + secs(6.0));
    assert_eq!(line.regulators()[0].address(), None);

    ask(&mut line, b"%$10Q000004\n", t0 + secs(7.0));
    // The band pre-heated since 4.5 s and cooled since 6 s: balancing waits for it, until 13 s.
    ask(&mut line, b"%415Q000000\n", t0 + secs(7.5));
    assert_eq!(
        fault(&mut line, 4, t0 + secs(12.9)),
        diagnostic::CALIBRATION_IN_PROGRESS
    );
    assert_eq!(fault(&mut line, 4, t0 + secs(13.2)), diagnostic::NONE);
    ask(&mut line, b"%416Q000000\n", t0 + secs(14.0));
    line.power_cycle(t0 + secs(15.0));
    assert_eq!(line.regulators()[0].address(), Some(addr(4)));
    assert_eq!(fault(&mut line, 4, t0 + secs(15.5)), diagnostic::NONE);
}

#[test]
fn a_refused_write_is_echoed_with_the_value_kept_and_the_client_sees_a_mismatch() {
    let (mut line, t0) = line_at_0();
    let item = Table::Settings
        .item(settings::SEALING_TEMPERATURE)
        .expect("exists");
    // 300 °C is three digits, but above the maximum working temperature (250 °C).
    let exchange = Exchange::new(
        addr(0).into(),
        Write::value(item, 300.0).expect("fits the item").into(),
    )
    .expect("addressed");
    let echo = ask(&mut line, &exchange.query_bytes(), t0 + secs(1.0));
    assert_eq!(echo.to_bytes(), b"%012R150180\n");
    assert!(matches!(
        exchange.classify(&echo),
        Classified::Mismatch(ExchangeError::EchoMismatch { .. })
    ));
    // A computed item keeps its value too.
    assert_eq!(
        ask(&mut line, b"%018Q110050\n", t0 + secs(1.5)).to_bytes(),
        b"%018R110010\n"
    );
    // An address beyond 7 written raw into machine item 14.
    assert_eq!(
        ask(&mut line, b"%011Q140009\n", t0 + secs(2.0)).to_bytes(),
        b"%011R140000\n"
    );
}

#[test]
fn writing_machine_item_14_moves_the_regulator_to_the_new_address() {
    let (mut line, t0) = line_at_0();
    // The echo still comes from the address the question went to.
    assert_eq!(
        ask(&mut line, b"%011Q140005\n", t0 + secs(1.0)).to_bytes(),
        b"%011R140005\n"
    );
    assert!(send(&mut line, b"%053Q990\n", t0 + secs(1.5)).is_empty());
    assert_eq!(fault(&mut line, 5, t0 + secs(2.0)), diagnostic::NONE);
}

#[test]
fn set_address_to_a_current_address_moves_that_regulator() {
    let t0 = Instant::now();
    let mut line = RegulatorBus::new(&[addr(0), addr(1)], t0).expect("two regulators");
    assert_eq!(
        ask(&mut line, b"%110Q000006\n", t0 + secs(1.0)).to_bytes(),
        b"%110R000006\n"
    );
    let addresses: Vec<Option<Address>> = line.regulators().iter().map(|r| r.address()).collect();
    assert_eq!(addresses, [Some(addr(0)), Some(addr(6))]);
}

#[test]
fn disabling_the_serial_interface_silences_the_regulator_until_power_cycle() {
    let (mut line, t0) = line_at_0();
    assert_eq!(
        ask(&mut line, b"%011Q130000\n", t0 + secs(1.0)).to_bytes(),
        b"%011R130000\n"
    );
    assert!(send(&mut line, b"%053Q990\n", t0 + secs(1.5)).is_empty());
    line.power_cycle(t0 + secs(2.0));
    assert_eq!(
        decode_one(&send(&mut line, b"%053Q990\n", t0 + secs(2.5))[0].bytes)
            .data()
            .len(),
        7
    );
}
