//! Our JSON against the SDK's own examples (the doc comments of SDK 2.1.1's classes),
//! field by field: every field we write is one the SDK's example has (or its class
//! declares), with the same JSON type where both have a value.

use std::time::Duration;

use serde_json::{Value, json};
use uuid::Uuid;

use crate::messages::*;
use crate::types::*;
use crate::{Envelope, Received};

fn handle() -> Handle {
    Handle::new("Panasonic.BM221.SN1234").unwrap()
}

/// 2018-10-31T15:13:31 at UTC−4, as the SDK's examples are.
fn at(seconds: i64) -> Time {
    let zone = jiff::tz::TimeZone::fixed(jiff::tz::offset(-4));
    Time::new(
        jiff::Timestamp::from_second(1_541_013_211 + seconds).unwrap(),
        &zone,
    )
}

fn id(n: u128) -> Uuid {
    Uuid::from_u128(n)
}

/// The JSON type of a value, for comparing shapes.
fn kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "bool",
        Value::Number(_) => "number",
        Value::String(_) => "string",
        Value::Array(_) => "array",
        Value::Object(_) => "object",
    }
}

/// Every field of `ours` is in `sdk` (or in `declared`, fields the SDK's class has but its
/// example leaves out), with the same JSON type when both are set; objects recursively.
#[track_caller]
fn same_shape(ours: &Value, sdk: &Value, declared: &[&str], path: &str) {
    let (Value::Object(ours), Value::Object(sdk)) = (ours, sdk) else {
        panic!("{path}: not objects: {ours} / {sdk}");
    };
    for (name, value) in ours {
        if name == "$type" && !sdk.contains_key("$type") {
            continue;
        }
        let Some(theirs) = sdk.get(name) else {
            assert!(
                declared.contains(&name.as_str()),
                "{path}.{name}: not in the SDK's example ({sdk:?})"
            );
            continue;
        };
        if value.is_null() || theirs.is_null() {
            continue;
        }
        assert_eq!(
            kind(value),
            kind(theirs),
            "{path}.{name}: {value} / {theirs}"
        );
        if value.is_object() {
            same_shape(value, theirs, declared, &format!("{path}.{name}"));
        }
    }
}

/// The body of `message` without its `$type`, which the SDK's examples leave out.
fn body(message: &Message) -> Value {
    let mut body = message.body();
    let object = body.as_object_mut().unwrap();
    assert_eq!(
        object.remove("$type"),
        Some(json!(format!("{}, CFX", message.name())))
    );
    body
}

fn placement_fault() -> Fault {
    Fault {
        placement: Some(Placement {
            fault_type: PlacementFaultType::PartsExhaust,
            program_step: 87,
            feeder: Some("7".into()),
            nozzle: Some(3),
        }),
        transaction_id: None,
        cause: FaultCause::Refill,
        severity: FaultSeverity::Error,
        fault_code: "2E03".into(),
        fault_occurrence_id: id(7),
        description: Some("parts exhausted at feeder 7".into()),
        occurred_at: at(0),
    }
}

#[test]
fn an_envelope_has_the_sdks_fields_its_version_and_the_body_with_its_type_first() {
    let sdk: Value = serde_json::from_str(
        r#"{
           "MessageName": "CFX.EndpointConnected",
           "Version": "1.7",
           "TimeStamp": "2018-03-26T16:52:25.3769532-04:00",
           "UniqueID": "f3b2c8ec-50b7-4c63-9cb3-2ed57c01880f",
           "Source": null,
           "Target": null,
           "RequestID": null,
           "MessageBody": {
             "CFXHandle": "SMTPlus.Model_21232.SN23123",
             "RequestNetworkUri": "amqp://host33/",
             "RequestTargetAddress": "/queue/SN23123"
            }
        }"#,
    )
    .unwrap();
    let message = Message::EndpointConnected(EndpointConnected {
        cfx_handle: handle(),
        request_network_uri: Some("amqp://127.0.0.1:5672/".into()),
        request_target_address: Some(handle().to_string()),
    });
    let envelope = Envelope {
        unique_id: id(1),
        ..Envelope::new(handle(), at(0), message)
    };
    let ours = envelope.to_json();
    same_shape(&ours, &sdk, &[], "envelope");
    assert_eq!(ours["Version"], "2.1");
    assert_eq!(ours["MessageName"], "CFX.EndpointConnected");
    assert_eq!(ours["TimeStamp"], "2018-10-31T15:13:31.0000000-04:00");
    assert_eq!(ours["UniqueID"], "00000000-0000-0000-0000-000000000001");
    assert_eq!(ours["Source"], "Panasonic.BM221.SN1234");
    assert_eq!(ours["MessageBody"]["$type"], "CFX.EndpointConnected, CFX");
    let text = String::from_utf8(envelope.to_bytes()).unwrap();
    assert!(
        text.contains(r#""MessageBody":{"$type":"CFX.EndpointConnected, CFX""#),
        "$type first: {text}"
    );
}

#[test]
fn a_state_change_with_the_fault_that_stopped_the_machine_is_the_sdks_second_example() {
    let sdk = json!({
      "OldState": 1100,
      "OldStateDuration": "00:00:25",
      "NewState": 5500,
      "RelatedFault": {
        "Cause": "MechanicalFailure",
        "Severity": "Error",
        "FaultCode": "ERROR 3943480",
        "FaultOccurrenceId": "3de0cfce-42f4-4302-982b-96dba4ec3de0",
        "Lane": null,
        "Stage": null,
        "SideLocation": "Unknown",
        "AccessType": "Unknown"
      }
    });
    let message = Message::StationStateChanged(StationStateChanged {
        old_state: ResourceState::PRODUCTIVE,
        old_state_duration: Some(TimeSpan(Duration::from_secs(25))),
        new_state: ResourceState::new(5500).unwrap(),
        related_fault: Some(Fault {
            placement: None,
            ..placement_fault()
        }),
    });
    let ours = body(&message);
    // The example leaves out what the Fault class declares besides.
    let fault_fields = [
        "TransactionID",
        "Description",
        "DescriptionTranslations",
        "OccurredAt",
        "DueDateTime",
    ];
    same_shape(&ours, &sdk, &fault_fields, "StationStateChanged");
    assert_eq!(ours["OldState"], 1100);
    assert_eq!(ours["NewState"], 5500);
    assert_eq!(ours["OldStateDuration"], "00:00:25");
    assert_eq!(ours["RelatedFault"]["FaultCode"], "2E03");
    assert_eq!(
        message.name(),
        "CFX.ResourcePerformance.StationStateChanged"
    );
    assert_eq!(message.topic(), "CFX.ResourcePerformance");
}

#[test]
fn parts_exhausted_is_an_smt_placement_fault_with_its_type_feeder_and_nozzle() {
    let sdk: Value = serde_json::from_str(
        r#"{
      "Fault": {
        "$type": "CFX.Structures.SMTPlacement.SMTPlacementFault, CFX",
        "PlacementFaultType": "PickupError",
        "ProgramStep": 56,
        "Designator": { "ReferenceDesignator": "R31", "UnitPosition": null, "PartNumber": "PN123456" },
        "MaterialLocation": {
          "LocationIdentifier": "UID23948348324",
          "LocationName": "SLOT47",
          "MaterialPackage": { "UniqueIdentifier": "UID34280923084932849", "InternalPartNumber": "IPN456465465465", "Quantity": 854.0 },
          "CarrierInformation": { "$type": "CFX.Structures.SMTPlacement.SMDTapeFeeder, CFX", "Name": "8MMFDR231" }
        },
        "HeadAndNozzle": { "HeadId": "HEAD1", "HeadNozzleNumber": 3, "NozzleType": "TYPE914", "UniqueIdentifier": "UID2389432849", "Name": "NOZZLE3243244" },
        "Cause": "MechanicalFailure",
        "Severity": "Error",
        "FaultCode": "ERROR 3943480",
        "FaultOccurrenceId": "a5c05bdc-41a3-4e50-b421-b084eb12ba2b",
        "Lane": 1,
        "Stage": { "StageSequence": 2, "StageName": "STAGE2", "StageType": "Work" },
        "SideLocation": "Unknown",
        "AccessType": "Unknown",
        "Description": null,
        "DescriptionTranslations": {},
        "OccurredAt": "2018-10-31T15:13:31.0552292-04:00",
        "DueDateTime": null
      }
    }"#,
    )
    .unwrap();
    let message = Message::FaultOccurred(FaultOccurred {
        fault: placement_fault(),
    });
    let ours = body(&message);
    same_shape(&ours, &sdk, &["TransactionID"], "FaultOccurred");
    let fault = &ours["Fault"];
    assert_eq!(fault["$type"], sdk["Fault"]["$type"]);
    assert_eq!(fault["PlacementFaultType"], "PartsExhaust");
    assert_eq!(fault["ProgramStep"], 87);
    assert_eq!(fault["MaterialLocation"]["LocationName"], "7");
    assert_eq!(fault["HeadAndNozzle"]["HeadNozzleNumber"], 3);
    assert_eq!(fault["Cause"], "Refill");
    assert_eq!(fault["OccurredAt"], "2018-10-31T15:13:31.0000000-04:00");
    assert_eq!(fault["FaultOccurrenceId"], id(7).to_string());

    // Its FaultCleared names the same occurrence.
    let sdk = json!({
      "FaultOccurrenceId": "22ac3c8a-9e6d-42f8-85b2-f51bf2224ecc",
      "Operator": { "OperatorIdentifier": "BADGE4486", "ActorType": "Human" }
    });
    let cleared = body(&Message::FaultCleared(FaultCleared {
        fault_occurrence_id: id(7),
        operator: None,
    }));
    same_shape(&cleared, &sdk, &[], "FaultCleared");
    assert_eq!(cleared["FaultOccurrenceId"], fault["FaultOccurrenceId"]);
}

#[test]
fn a_board_is_a_work_started_and_a_work_completed_with_one_transaction() {
    let started_sdk = json!({
      "PrimaryIdentifier": null,
      "HermesIdentifier": null,
      "TransactionID": "2c24590d-39c5-4039-96a5-91900cecedfa",
      "Lane": 1,
      "UnitCount": 2,
      "Units": [],
      "RecipeName": "Recipe1",
      "Revision": null,
      "RelevantSurface": "PrimarySurface",
      "WorkOrderIdentifier": null
    });
    let completed_sdk = json!({
      "TransactionID": "2c24590d-39c5-4039-96a5-91900cecedfa",
      "Result": "Completed",
      "PrimaryIdentifier": null,
      "HermesIdentifier": null,
      "UnitCount": 0,
      "Units": []
    });
    let started = body(&Message::WorkStarted(WorkStarted::board(
        id(9),
        Some("MAINBOARD-A".into()),
    )));
    let completed = body(&Message::WorkCompleted(WorkCompleted::board(id(9))));
    same_shape(&started, &started_sdk, &[], "WorkStarted");
    same_shape(
        &completed,
        &completed_sdk,
        &["PerformanceImpacts"],
        "WorkCompleted",
    );
    assert_eq!(started["TransactionID"], completed["TransactionID"]);
    assert_eq!(completed["Result"], "Completed");
}

#[test]
fn placements_recipes_heartbeats_and_the_station_going_off_and_on_line_match_the_sdk() {
    let cases = [
        (
            Message::ComponentsPlaced(ComponentsPlaced {
                start_time: at(0),
                end_time: at(600),
                total_components_placed: 875,
                total_components_not_placed: 45,
            }),
            json!({
              "StartTime": "2018-04-05T09:28:06.161835-04:00",
              "EndTime": "2018-04-05T09:38:06.161835-04:00",
              "TotalComponentsPlaced": 875,
              "TotalComponentsNotPlaced": 45
            }),
            &[][..],
        ),
        (
            // The SDK's example has a typographic quote and misses two commas; fixed here.
            Message::RecipeActivated(RecipeActivated::named("MAINBOARD-A")),
            json!({
              "RecipeName": "RECIPE3234",
              "Revision": "B",
              "Lane": 1,
              "Stage": null,
              "ExpectedCycleTime": 60,
              "ExpectedUnitsPerWorkTransaction": 1,
              "NumberOfComponentsPerUnit": 500,
              "WorkOrderIdentifier": { "WorkOrderId": "WO-1000-1000", "Batch": "WO-1000-1000-B1" },
              "TargetQuantity": 500.0,
              "RelevantSurface": "PrimarySurface",
              "RecipeStagesInformation": []
            }),
            &["ExpectedWorkTime"][..],
        ),
        (
            Message::Heartbeat(Heartbeat {
                cfx_handle: handle(),
                heartbeat_frequency: TimeSpan(Duration::from_secs(60)),
                active_faults: vec![placement_fault()],
                active_recipes: Vec::new(),
            }),
            json!({
                "CFXHandle": "SMTPlus.Model_21232.SN23123",
                "HeartbeatFrequency": "00:01:00"
            }),
            &["ActiveFaults", "ActiveRecipes"][..],
        ),
        (
            Message::StationOffline(StationOffline {}),
            json!({}),
            &[][..],
        ),
        (
            Message::StationOnline(StationOnline {
                offline_duration: Some(TimeSpan(Duration::from_secs(23 * 60))),
            }),
            json!({ "OfflineDuration": "00:23:00" }),
            &[][..],
        ),
        (
            Message::EndpointShuttingDown(EndpointShuttingDown {
                cfx_handle: handle(),
            }),
            json!({ "CFXHandle": "SMTPlus.Model_21232.SN23123" }),
            &[][..],
        ),
    ];
    for (message, sdk, declared) in cases {
        let ours = body(&message);
        same_shape(&ours, &sdk, declared, message.name());
    }
}

#[test]
fn the_root_topics_answers_match_the_sdk() {
    let there = ThereResponse {
        result: RequestResult::success(),
        cfx_handle: handle(),
        request_network_uri: Some("amqp://127.0.0.1:5672/".into()),
        request_target_address: Some(handle().to_string()),
    };
    let sdk = json!({
      "Result": { "Result": "Success", "ResultCode": 0, "Message": null },
      "CFXHandle": "SMTPlus.Model_21232.SN23123",
      "RequestNetworkUri": "amqp://host33/",
      "RequestTargetAddress": "/queue/SN23123"
    });
    same_shape(
        &body(&Message::AreYouThereResponse(there.clone())),
        &sdk,
        &[],
        "AreYouThereResponse",
    );
    same_shape(
        &body(&Message::WhoIsThereResponse(there)),
        &sdk,
        &[],
        "WhoIsThereResponse",
    );
    let information = body(&Message::GetEndpointInformationResponse(
        GetEndpointInformationResponse {
            result: RequestResult::success(),
            endpoint_information: EndpointInformation {
                cfx_handle: handle(),
                cfx_version: "2.1".into(),
                request_network_uri: None,
                request_target_address: None,
                unique_identifier: None,
                friendly_name: Some("Placer 1".into()),
                vendor: Some("Panasonic".into()),
                model_number: Some("BM221".into()),
                serial_number: None,
                software_version: Some("cellbus 0.1.0".into()),
            },
        },
    ));
    let sdk = json!({
      "Result": { "Result": "Success", "ResultCode": 0, "Message": null },
      "EndpointInformation": {
        "CFXHandle": "SMTPlus.Model_21232.SN23123",
        "CFXVersion": "1.0",
        "RequestNetworkUri": "amqp://host55:5688/",
        "RequestTargetAddress": "/queue/SN23123",
        "UniqueIdentifier": "UID1111111111111111",
        "FriendlyName": "SMD Printer 23123",
        "Vendor": "SMT Plus",
        "ModelNumber": "Model_11111",
        "SerialNumber": "SNSN23123",
        "SoftwareVersion": "18.5.4",
        "FirmwareVersion": "1.6.13"
      }
    });
    same_shape(&information, &sdk, &[], "GetEndpointInformationResponse");
    let refused = body(&Message::NotSupportedResponse(NotSupportedResponse {
        request_result: RequestResult::failed("Unknown message"),
    }));
    assert_eq!(
        refused,
        json!({ "RequestResult": { "Result": "Failed", "ResultCode": 0, "Message": "Unknown message" } })
    );
}

#[test]
fn an_amqp_message_carries_the_sdks_subject_content_type_and_application_properties() {
    let envelope = Envelope {
        unique_id: id(3),
        ..Envelope::new(handle(), at(0), Message::StationOffline(StationOffline {}))
    };
    let amqp = envelope.amqp();
    assert_eq!(amqp.message_id, "00000000-0000-0000-0000-000000000003");
    assert_eq!(
        amqp.subject,
        "Panasonic.BM221.SN1234.CFX.ResourcePerformance.StationOffline"
    );
    assert_eq!(amqp.content_type, "application/json; charset=\"utf-8\"");
    assert_eq!(amqp.creation_time_ms, 1_541_013_211_000);
    assert_eq!(amqp.reply_to, "Panasonic.BM221.SN1234");
    assert_eq!(
        amqp.application,
        [
            ("cfx-topic", Some("CFX.ResourcePerformance".to_owned())),
            (
                "cfx-message",
                Some("CFX.ResourcePerformance.StationOffline".to_owned())
            ),
            ("cfx-handle", Some("Panasonic.BM221.SN1234".to_owned())),
            ("cfx-target", None),
        ]
    );
}

#[test]
fn a_message_kept_as_its_json_is_sent_again_with_the_same_amqp_properties() {
    let mut envelope = Envelope {
        unique_id: id(4),
        ..Envelope::new(handle(), at(0), Message::StationOffline(StationOffline {}))
    };
    envelope.target = Some(Handle::new("Line1.MES").unwrap());
    envelope.request_id = Some("req-7".to_owned());
    let kept = Received::decode(&envelope.to_bytes()).unwrap();
    assert_eq!(kept[0].amqp().unwrap(), envelope.amqp());

    let headless = Received::decode(br#"{"MessageName": "CFX.Heartbeat"}"#).unwrap();
    assert_eq!(
        headless[0].amqp().unwrap_err().to_string(),
        "not a CFX envelope: CFX.Heartbeat has no UniqueID"
    );
}

#[test]
fn time_spans_are_written_and_read_as_dotnet_writes_them() {
    for (duration, text) in [
        (Duration::from_secs(85), "00:01:25"),
        (Duration::from_secs(23 * 60), "00:23:00"),
        (Duration::from_secs(93_784), "1.02:03:04"),
        (Duration::from_millis(500), "00:00:00.5000000"),
        (Duration::new(1, 1_234_567_800), "00:00:02.2345678"),
    ] {
        assert_eq!(TimeSpan(duration).to_string(), text);
        let read: TimeSpan = serde_json::from_value(json!(text)).unwrap();
        assert_eq!(read.to_string(), text);
    }
    for wrong in ["", "1:2", "00:60:00", "00:00:00.12345678", "x"] {
        assert!(
            serde_json::from_value::<TimeSpan>(json!(wrong)).is_err(),
            "{wrong}"
        );
    }
}

#[test]
fn only_cfx_resource_states_and_usable_handles_can_be_made() {
    assert_eq!(ResourceState::new(5500).unwrap().code(), 5500);
    assert_eq!(ResourceState::new(2202).unwrap().code(), 2202);
    for code in [0, 1234, 7000, 5501] {
        let error = ResourceState::new(code).unwrap_err();
        assert!(
            error.to_string().starts_with(&format!("{code} is not")),
            "{error}"
        );
    }
    for wrong in ["", "Panasonic BM221", "tab\there", &"x".repeat(257)] {
        assert!(Handle::new(wrong).is_err(), "{wrong:?}");
    }
    assert_eq!(handle().as_str(), "Panasonic.BM221.SN1234");
}

#[test]
fn received_envelopes_are_read_one_or_a_batch_and_garbage_is_refused_with_why() {
    let one = Envelope {
        unique_id: id(4),
        ..Envelope::new(
            handle(),
            at(5),
            Message::StationOnline(StationOnline {
                offline_duration: None,
            }),
        )
    };
    let received = Received::decode(&one.to_bytes()).unwrap();
    assert_eq!(received.len(), 1);
    assert_eq!(
        received[0].message_name,
        "CFX.ResourcePerformance.StationOnline"
    );
    assert_eq!(received[0].unique_id, Some(id(4)));
    assert_eq!(
        received[0].time_stamp.as_ref().map(Time::timestamp),
        Some(at(5).timestamp())
    );
    let batch = Envelope::batch_bytes(&[one.clone(), one]);
    assert_eq!(Received::decode(&batch).unwrap().len(), 2);
    let error = Received::decode(b"{\"MessageName\": 7}").unwrap_err();
    assert!(
        error.to_string().starts_with("not a CFX envelope: "),
        "{error}"
    );
    assert!(Received::decode(b"\x00garbage").is_err());
}
