use super::*;

const JBC: SerialSettings = SerialSettings::new_8e1(19200);

#[test]
fn serial_url_takes_path_speed_and_framing() {
    let e = Endpoint::parse("serial:///dev/ttyUSB0?baud=9600&framing=8N2", JBC).unwrap();
    assert_eq!(
        e,
        Endpoint::Serial {
            path: "/dev/ttyUSB0".into(),
            settings: SerialSettings {
                stop_bits: StopBits::Two,
                ..SerialSettings::new_8n1(9600)
            },
            rs485: Rs485::default(),
        }
    );
}

#[test]
fn serial_url_without_options_uses_the_protocol_defaults() {
    let e = Endpoint::parse("serial:///dev/ttyS0", JBC).unwrap();
    assert_eq!(e.line_settings(), Some(JBC));
    assert_eq!(e.to_string(), "serial:///dev/ttyS0?baud=19200&framing=8E1");
}

#[test]
fn a_bare_device_path_is_a_serial_endpoint() {
    let e = Endpoint::parse("/dev/ttyACM3", JBC).unwrap();
    assert!(matches!(e, Endpoint::Serial { path, .. } if path == "/dev/ttyACM3"));
}

#[test]
fn every_jbc_speed_is_accepted() {
    for baud in [
        1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 250000, 460800, 500000,
    ] {
        let e = Endpoint::parse(&format!("serial:///dev/ttyS0?baud={baud}"), JBC).unwrap();
        assert_eq!(e.line_settings().unwrap().baud, baud);
    }
}

#[test]
fn rs485_options_are_parsed() {
    let e = Endpoint::parse("serial:///dev/ttyUSB1?rs485=rts&echo=discard", JBC).unwrap();
    let Endpoint::Serial { rs485, .. } = e else {
        panic!("serial expected")
    };
    assert_eq!(
        rs485,
        Rs485 {
            direction: Some(DirectionControl::Rts),
            echo: Echo::Discard
        }
    );
}

#[test]
fn tcp_url_takes_host_port_and_optional_line_speed() {
    let e = Endpoint::parse("tcp://127.0.0.1:4001", JBC).unwrap();
    assert_eq!(
        e,
        Endpoint::Tcp {
            host: "127.0.0.1".into(),
            port: 4001,
            line: None,
            framing: TcpFraming::Raw,
        }
    );
    assert!(!e.is_mbap());
    let e = Endpoint::parse("tcp://[::1]:4001?baud=9600&framing=8N1", JBC).unwrap();
    assert_eq!(e.line_settings(), Some(SerialSettings::new_8n1(9600)));
    assert_eq!(e.to_string(), "tcp://[::1]:4001?baud=9600&framing=8N1");
}

#[test]
fn modbus_tcp_url_takes_host_and_port_502_unless_given() {
    let e = Endpoint::parse("modbus-tcp://192.0.2.20:1502", JBC).unwrap();
    assert_eq!(
        e,
        Endpoint::Tcp {
            host: "192.0.2.20".into(),
            port: 1502,
            line: None,
            framing: TcpFraming::Mbap,
        }
    );
    assert!(e.is_mbap());
    assert_eq!(e.line_settings(), None, "no serial timing on Modbus TCP");
    assert_eq!(e.to_string(), "modbus-tcp://192.0.2.20:1502");
    let e = Endpoint::parse("modbus-tcp://plc.local", JBC).unwrap();
    assert_eq!(e.to_string(), "modbus-tcp://plc.local:502");
    let e = Endpoint::parse("modbus-tcp://[::1]:5020", JBC).unwrap();
    assert_eq!(e.to_string(), "modbus-tcp://[::1]:5020");
}

#[test]
fn modbus_tcp_url_refuses_serial_options_and_a_missing_host() {
    let err = |t| Endpoint::parse(t, JBC).unwrap_err().to_string();
    assert!(
        err("modbus-tcp://127.0.0.1:502?baud=9600").contains("unknown option \"baud\""),
        "{}",
        err("modbus-tcp://127.0.0.1:502?baud=9600")
    );
    assert!(err("modbus-tcp://").contains("needs a host"));
}

#[test]
fn bad_urls_are_refused_naming_the_bad_part() {
    let err = |t| Endpoint::parse(t, JBC).unwrap_err().to_string();
    assert!(err("serial:///dev/ttyS0?baud=fast").contains("baud=\"fast\""));
    assert!(err("serial:///dev/ttyS0?baud=0").contains("from 50 to 4000000"));
    assert!(err("serial:///dev/ttyS0?framing=9X1").contains("parity N/E/O"));
    assert!(err("serial:///dev/ttyS0?parity=E").contains("unknown option \"parity\""));
    assert!(err("serial:///dev/ttyS0?rs485=cts").contains("rts, dtr"));
    assert!(err("http://example.invalid/").contains("scheme \"http\""));
    assert!(err("tcp://127.0.0.1").contains("needs a host and a port"));
    assert!(err("serial://").contains("names no serial device"));
    assert!(err("").contains("names no serial device"));
    assert!(err("pty/jbc1?baud=fast").contains("baud=\"fast\""));
}

#[test]
fn a_path_without_a_scheme_is_a_serial_device_relative_to_the_working_directory() {
    for text in ["pty/jbc1", "./pty/jbc1", "../cell/pty/jbc1", "ttyUSB0"] {
        let e = Endpoint::parse(text, JBC).unwrap();
        assert_eq!(
            e,
            Endpoint::Serial {
                path: text.into(),
                settings: JBC,
                rs485: Rs485::default(),
            }
        );
        assert_eq!(e.to_string(), format!("{text}?baud=19200&framing=8E1"));
        assert_eq!(Endpoint::parse(&e.to_string(), JBC).unwrap(), e);
    }
    let e = Endpoint::parse("pty/thermosald?baud=9600&framing=8N1&echo=discard", JBC).unwrap();
    assert_eq!(e.line_settings(), Some(SerialSettings::new_8n1(9600)));
    assert!(matches!(e, Endpoint::Serial { path, rs485, .. }
        if path == "pty/thermosald" && rs485.echo == Echo::Discard));
}

#[test]
fn a_bare_absolute_path_takes_options_as_its_url_does() {
    let bare = Endpoint::parse("/dev/ttyUSB1?baud=9600&rs485=rts", JBC).unwrap();
    let url = Endpoint::parse("serial:///dev/ttyUSB1?baud=9600&rs485=rts", JBC).unwrap();
    assert_eq!(bare, url);
    assert_eq!(
        bare.to_string(),
        "serial:///dev/ttyUSB1?baud=9600&framing=8E1&rs485=rts"
    );
}

#[test]
fn a_serial_url_with_a_host_part_is_refused_rather_than_read_as_an_absolute_path() {
    let err = Endpoint::parse("serial://pty/jbc1", JBC).unwrap_err();
    assert_eq!(
        err,
        EndpointError::SerialHost {
            url: "serial://pty/jbc1".into(),
            host: "pty".into(),
            path: "/jbc1".into(),
        }
    );
    assert_eq!(
        err.to_string(),
        "endpoint \"serial://pty/jbc1\" reads \"pty\" as a host name, and a serial port has \
         none; write serial:///pty/jbc1 (three slashes) for the absolute path /pty/jbc1, or \
         pty/jbc1 without serial:// for a path relative to the working directory"
    );
    let err = Endpoint::parse("serial://dev/ttyUSB0?baud=9600", JBC).unwrap_err();
    assert!(
        err.to_string()
            .contains("write serial:///dev/ttyUSB0 (three slashes)"),
        "{err}"
    );
}

#[test]
fn host_and_port_without_a_scheme_is_refused_naming_the_urls_to_write() {
    for text in ["127.0.0.1:4001", "localhost:4001", "[::1]:502"] {
        let err = Endpoint::parse(text, JBC).unwrap_err();
        assert_eq!(err, EndpointError::HostPort { url: text.into() });
        assert!(
            err.to_string().contains(&format!("write tcp://{text}")),
            "{err}"
        );
    }
}

#[test]
fn character_time_counts_start_parity_and_stop_bits() {
    assert_eq!(SerialSettings::new_8n1(9600).bits_per_char(), 10);
    assert_eq!(SerialSettings::new_8e1(19200).bits_per_char(), 11);
    assert_eq!(
        SerialSettings::new_8n1(9600).time_for(960),
        Duration::from_secs(1)
    );
    assert_eq!(
        SerialSettings::new_8n1(10_000).char_time(),
        Duration::from_millis(1)
    );
}
