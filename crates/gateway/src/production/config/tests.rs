use crate::testing::config::{ONE, PLACER, parse, refused};

#[test]
fn shifts_are_read_in_the_cells_time_zone_with_their_days_and_breaks() {
    let config = parse(&format!(
        "time_zone = \"Europe/Berlin\"\n\
         [[shift]]\nname = \"early\"\ndays = [\"mon-fri\"]\nstart = \"06:00\"\nend = \"14:00\"\n\
         breaks = [{{ start = \"09:00\", end = \"09:15\" }}]\n\
         [[shift]]\nname = \"night\"\ndays = [\"sun\", \"mon\"]\nstart = \"22:00\"\nend = \"06:00\"\n{ONE}"
    ))
    .unwrap();
    let shifts = &config.shifts;
    assert_eq!(shifts.zone_name(), "Europe/Berlin");
    let names: Vec<&str> = shifts.shifts().iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["early", "night"]);
    assert_eq!(shifts.shifts()[0].days.len(), 5);
    assert_eq!(shifts.shifts()[0].breaks.len(), 1);
    assert_eq!(shifts.shifts()[1].days.len(), 2);
}

#[test]
fn a_cell_without_shifts_has_one_of_24_hours() {
    let config = parse(ONE).unwrap();
    let shifts = config.shifts.shifts();
    assert_eq!(shifts.len(), 1);
    assert_eq!(shifts[0].name, "day");
    assert_eq!(shifts[0].days.len(), 7);
}

#[test]
fn shift_mistakes_are_refused_where_they_are() {
    refused(
        &format!("time_zone = \"Mars/Olympus\"\n{ONE}"),
        1,
        13,
        "time zone \"Mars/Olympus\" is not in the tz database",
    );
    let shift = |body: &str| format!("[[shift]]\nname = \"early\"\n{body}\n{ONE}");
    refused(
        &shift("start = \"6am\"\nend = \"14:00\""),
        3,
        9,
        "shift \"early\": start \"6am\" is not a time of day; write HH:MM",
    );
    refused(
        &shift("days = [\"mon\", \"funday\"]\nstart = \"06:00\"\nend = \"14:00\""),
        3,
        8,
        "\"funday\" is not a weekday",
    );
    refused(
        &shift(
            "start = \"06:00\"\nend = \"14:00\"\nbreaks = [{ start = \"13:30\", end = \"14:30\" }]",
        ),
        5,
        21,
        "the break 13:30–14:30 is not within the shift 06:00–14:00",
    );
    refused(
        &shift("start = \"06:00\"\nstop = \"14:00\""),
        4,
        1,
        "unknown field `stop`",
    );
    refused(
        &format!(
            "[[shift]]\nname = \"a\"\nstart = \"06:00\"\nend = \"14:00\"\n\
             [[shift]]\nname = \"a\"\nstart = \"14:00\"\nend = \"22:00\"\n{ONE}"
        ),
        6,
        8,
        "shift name \"a\" is used twice",
    );
}

#[test]
fn a_night_break_after_midnight_is_within_its_shift() {
    let config = parse(&format!(
        "[[shift]]\nname = \"night\"\nstart = \"22:00\"\nend = \"06:00\"\n\
         breaks = [{{ start = \"02:00\", end = \"02:30\" }}]\n{ONE}"
    ))
    .unwrap();
    assert_eq!(config.shifts.shifts()[0].breaks.len(), 1);
}

#[test]
fn a_device_moves_its_states_to_other_codes_by_name() {
    let config = parse(&format!(
        "{PLACER}states = {{ ready = 2200, setup = 4400 }}\n"
    ))
    .unwrap();
    let driver = &config.lines[0].devices[0].driver;
    assert_eq!(driver.states["ready"].get(), 2200);
    assert_eq!(driver.states["setup"].get(), 4400);
    refused(
        &format!("{PLACER}states = {{ idle = 2200 }}\n"),
        9,
        10,
        "panasonic devices have no machine state \"idle\"; their states: \"run\", \"ready\"",
    );
    refused(
        &format!("{PLACER}states = {{ ready = 2250 }}\n"),
        9,
        10,
        "the codes of its thousand are 2000 standby",
    );
    let meter = "[[line]]\nname = \"m\"\nendpoint = \"modbus-tcp://192.0.2.1:502\"\n\
                 [[line.device]]\nid = \"meter\"\nprotocol = \"modbus\"\naddress = 1\n\
                 states = { run = 1100 }\n\
                 [[line.device.register]]\nname = \"power\"\naddress = 0\ntype = \"float32\"\n";
    let error = parse(meter).unwrap_err().to_string();
    assert!(
        error.contains("modbus devices report no machine states"),
        "{error}"
    );
}

#[test]
fn a_placement_machine_takes_its_ideal_cycles_micro_stops_and_good_board_count() {
    let config = parse(&format!(
        "{PLACER}[line.device.production]\n\
         ideal_cycle = {{ \"PCB-A\" = \"40s\", \"*\" = \"45s\" }}\n\
         micro_stop = \"2m\"\ngood_boards = \"placer1.boards_produced\"\n"
    ))
    .unwrap();
    let production = config.lines[0].devices[0].production.clone().unwrap();
    assert_eq!(production.ideal_cycle.unwrap().as_secs(), 45);
    assert_eq!(production.ideal_cycle_by_program["PCB-A"].as_secs(), 40);
    assert_eq!(production.micro_stop.unwrap().as_secs(), 120);
    assert_eq!(
        production.good_boards.unwrap().as_str(),
        "placer1.boards_produced"
    );
    let one = parse(&format!(
        "{PLACER}[line.device.production]\nideal_cycle = \"42s\"\n"
    ))
    .unwrap();
    let production = one.lines[0].devices[0].production.clone().unwrap();
    assert_eq!(production.ideal_cycle.unwrap().as_secs(), 42);
}

#[test]
fn production_mistakes_are_refused_where_they_are() {
    let table = |body: &str| format!("{PLACER}[line.device.production]\n{body}\n");
    refused(
        &table("ideal_cycle = \"fast\""),
        10,
        15,
        "ideal_cycle \"fast\" is not a duration",
    );
    refused(
        &table("good_boards = \"aoi\""),
        10,
        15,
        "good_boards \"aoi\" is not a point id (device.point)",
    );
    let error = parse(&table("good_boards = \"aoi1.good\""))
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("good_boards names aoi1.good, but the cell has no device \"aoi1\""),
        "{error}"
    );
    refused(
        &format!("{ONE}[line.device.production]\nideal_cycle = \"42s\"\n"),
        9,
        1,
        "jbc devices count no production",
    );
}
