//! The message bodies: the root topic's (every endpoint's) and those a placement machine
//! publishes, each with the SDK's field names in its order, `null` where the SDK writes
//! `null` for a value nobody set. [`Message`] puts a body in its envelope with its full
//! name (`CFX.ResourcePerformance.StationStateChanged`) and its `$type`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use uuid::Uuid;

use crate::types::{
    FaultCause, FaultSeverity, Handle, PlacementFaultType, RequestResult, ResourceState, Time,
    TimeSpan, WorkResult,
};

/// A fault (SDK `Fault`), or an SMT placement fault (`SMTPlacementFault`) when it has a
/// [`Placement`].
#[derive(Debug, Clone, PartialEq)]
pub struct Fault {
    /// What a placement machine knows of it: the kind, the program step, the nozzle and
    /// the feeder.
    pub placement: Option<Placement>,
    /// The work transaction it concerns, if any.
    pub transaction_id: Option<Uuid>,
    /// The cause.
    pub cause: FaultCause,
    /// How grave.
    pub severity: FaultSeverity,
    /// The machine's own code (`E0030`).
    pub fault_code: String,
    /// Pairs its `FaultOccurred` with its `FaultCleared`.
    pub fault_occurrence_id: Uuid,
    /// Words.
    pub description: Option<String>,
    /// When it happened.
    pub occurred_at: Time,
}

/// What an SMT placement fault adds to a fault.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// The kind.
    pub fault_type: PlacementFaultType,
    /// The program step (0 when not known).
    pub program_step: i32,
    /// The feeder (slot), if known.
    pub feeder: Option<String>,
    /// The nozzle, if known.
    pub nozzle: Option<i32>,
}

/// The JSON of a fault, in the SDK's order.
#[derive(Serialize)]
#[serde(rename_all = "PascalCase")]
struct FaultJson<'a> {
    #[serde(rename = "$type", skip_serializing_if = "Option::is_none")]
    type_name: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    placement_fault_type: Option<PlacementFaultType>,
    #[serde(skip_serializing_if = "Option::is_none")]
    program_step: Option<i32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    designator: Option<serde_json::Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    material_location: Option<serde_json::Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    head_and_nozzle: Option<serde_json::Value>,
    #[serde(rename = "TransactionID")]
    transaction_id: Option<Uuid>,
    cause: FaultCause,
    severity: FaultSeverity,
    fault_code: &'a str,
    fault_occurrence_id: Uuid,
    lane: Option<i32>,
    stage: Option<()>,
    side_location: &'static str,
    access_type: &'static str,
    description: Option<&'a str>,
    description_translations: BTreeMap<String, String>,
    occurred_at: &'a Time,
    due_date_time: Option<()>,
}

/// The `$type` of an SMT placement fault.
pub const PLACEMENT_FAULT_TYPE: &str = "CFX.Structures.SMTPlacement.SMTPlacementFault, CFX";

impl Serialize for Fault {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let p = self.placement.as_ref();
        FaultJson {
            type_name: p.map(|_| PLACEMENT_FAULT_TYPE),
            placement_fault_type: p.map(|p| p.fault_type),
            program_step: p.map(|p| p.program_step),
            designator: p.map(|_| {
                serde_json::json!({"ReferenceDesignator": null, "UnitPosition": null, "PartNumber": null})
            }),
            material_location: p.map(|p| {
                serde_json::json!({
                    "LocationIdentifier": null,
                    "LocationName": p.feeder,
                    "MaterialPackage": null,
                    "CarrierInformation": null,
                })
            }),
            head_and_nozzle: p.map(|p| {
                serde_json::json!({
                    "HeadId": null,
                    "HeadNozzleNumber": p.nozzle,
                    "NozzleType": null,
                    "UniqueIdentifier": null,
                    "Name": p.nozzle.map(|n| format!("NOZZLE{n}")),
                })
            }),
            transaction_id: self.transaction_id,
            cause: self.cause,
            severity: self.severity,
            fault_code: &self.fault_code,
            fault_occurrence_id: self.fault_occurrence_id,
            lane: None,
            stage: None,
            side_location: "Unknown",
            access_type: "Unknown",
            description: self.description.as_deref(),
            description_translations: BTreeMap::new(),
            occurred_at: &self.occurred_at,
            due_date_time: None,
        }
        .serialize(serializer)
    }
}

/// `CFX.EndpointConnected`: the endpoint joined the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct EndpointConnected {
    /// Its handle.
    #[serde(rename = "CFXHandle")]
    pub cfx_handle: Handle,
    /// Where its requests go (`amqp://host:5672/`), if it listens.
    pub request_network_uri: Option<String>,
    /// The address there (its handle).
    pub request_target_address: Option<String>,
}

/// `CFX.EndpointShuttingDown`: the endpoint leaves the network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EndpointShuttingDown {
    /// Its handle.
    #[serde(rename = "CFXHandle")]
    pub cfx_handle: Handle,
}

/// `CFX.Heartbeat`: the endpoint is there, with its faults.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct Heartbeat {
    /// Its handle.
    #[serde(rename = "CFXHandle")]
    pub cfx_handle: Handle,
    /// How often it beats.
    pub heartbeat_frequency: TimeSpan,
    /// The faults not cleared yet.
    pub active_faults: Vec<Fault>,
    /// The recipes in use (none said by a placement machine's host protocol).
    pub active_recipes: Vec<()>,
}

/// `CFX.AreYouThereResponse`, `CFX.WhoIsThereResponse`: the endpoint answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct ThereResponse {
    /// Success.
    pub result: RequestResult,
    /// Its handle.
    #[serde(rename = "CFXHandle")]
    pub cfx_handle: Handle,
    /// Where its requests go.
    pub request_network_uri: Option<String>,
    /// The address there.
    pub request_target_address: Option<String>,
}

/// What `CFX.GetEndpointInformationResponse` tells of the endpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct EndpointInformation {
    /// Its handle.
    #[serde(rename = "CFXHandle")]
    pub cfx_handle: Handle,
    /// The CFX version it speaks.
    #[serde(rename = "CFXVersion")]
    pub cfx_version: String,
    /// Where its requests go.
    pub request_network_uri: Option<String>,
    /// The address there.
    pub request_target_address: Option<String>,
    /// The machine's own id, if known.
    pub unique_identifier: Option<String>,
    /// Its name for people.
    pub friendly_name: Option<String>,
    /// Who made it.
    pub vendor: Option<String>,
    /// Its model.
    pub model_number: Option<String>,
    /// Its serial number.
    pub serial_number: Option<String>,
    /// The software speaking for it (cellbus and its version).
    pub software_version: Option<String>,
}

/// `CFX.GetEndpointInformationResponse`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct GetEndpointInformationResponse {
    /// Success.
    pub result: RequestResult,
    /// The endpoint.
    pub endpoint_information: EndpointInformation,
}

/// `CFX.NotSupportedResponse`: the endpoint does not handle that request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "PascalCase")]
pub struct NotSupportedResponse {
    /// Failed, with why.
    pub request_result: RequestResult,
}

/// `CFX.ResourcePerformance.StationStateChanged`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct StationStateChanged {
    /// The state it left.
    pub old_state: ResourceState,
    /// How long it was in it (`null`: unknown, as after the gateway's own restart).
    pub old_state_duration: Option<TimeSpan>,
    /// The state it is in now.
    pub new_state: ResourceState,
    /// The fault that stopped it, if one did.
    pub related_fault: Option<Fault>,
}

/// `CFX.ResourcePerformance.FaultOccurred`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct FaultOccurred {
    /// The fault.
    pub fault: Fault,
}

/// `CFX.ResourcePerformance.FaultCleared`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct FaultCleared {
    /// Its `FaultOccurred`'s id.
    pub fault_occurrence_id: Uuid,
    /// Who cleared it (not known from the host protocol).
    pub operator: Option<()>,
}

/// `CFX.Production.WorkStarted`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct WorkStarted {
    /// The board's barcode (not known from the host protocol).
    pub primary_identifier: Option<String>,
    /// Its Hermes id.
    pub hermes_identifier: Option<String>,
    /// Pairs it with its `WorkCompleted`.
    #[serde(rename = "TransactionID")]
    pub transaction_id: Uuid,
    /// The lane.
    pub lane: Option<i32>,
    /// Units on the board (0: not known).
    pub unit_count: i32,
    /// The units (none known).
    pub units: Vec<()>,
    /// The program in use.
    pub recipe_name: Option<String>,
    /// Its revision.
    pub revision: Option<String>,
    /// The surface worked (`Unspecified`).
    pub relevant_surface: &'static str,
    /// The work order.
    pub work_order_identifier: Option<()>,
}

/// `CFX.Production.WorkCompleted`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct WorkCompleted {
    /// Its `WorkStarted`'s transaction.
    #[serde(rename = "TransactionID")]
    pub transaction_id: Uuid,
    /// How it ended.
    pub result: WorkResult,
    /// The board's barcode.
    pub primary_identifier: Option<String>,
    /// Its Hermes id.
    pub hermes_identifier: Option<String>,
    /// Units (0: not known).
    pub unit_count: i32,
    /// The units.
    pub units: Vec<()>,
    /// What slowed it.
    pub performance_impacts: Vec<()>,
}

impl WorkStarted {
    /// A board's work started, in transaction `transaction_id`, under the program
    /// `recipe_name` if known; nothing else known (a host protocol that reports boards
    /// without identifiers).
    pub fn board(transaction_id: Uuid, recipe_name: Option<String>) -> Self {
        Self {
            primary_identifier: None,
            hermes_identifier: None,
            transaction_id,
            lane: None,
            unit_count: 0,
            units: Vec::new(),
            recipe_name,
            revision: None,
            relevant_surface: "Unspecified",
            work_order_identifier: None,
        }
    }
}

impl WorkCompleted {
    /// The board of transaction `transaction_id` completed; nothing else known.
    pub fn board(transaction_id: Uuid) -> Self {
        Self {
            transaction_id,
            result: WorkResult::Completed,
            primary_identifier: None,
            hermes_identifier: None,
            unit_count: 0,
            units: Vec::new(),
            performance_impacts: Vec::new(),
        }
    }
}

/// `CFX.ResourcePerformance.SMTPlacement.ComponentsPlaced`: the parts placed in a window.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct ComponentsPlaced {
    /// The window's start.
    pub start_time: Time,
    /// Its end.
    pub end_time: Time,
    /// Parts placed.
    pub total_components_placed: u64,
    /// Parts picked but not placed (pickup and recognition errors).
    pub total_components_not_placed: u64,
}

/// `CFX.Production.RecipeActivated`: a program was selected.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct RecipeActivated {
    /// The program.
    pub recipe_name: String,
    /// Its revision.
    pub revision: Option<String>,
    /// The lane.
    pub lane: Option<i32>,
    /// The stage.
    pub stage: Option<()>,
    /// The expected cycle time, s (0: not known).
    pub expected_cycle_time: f64,
    /// The expected work time.
    pub expected_work_time: Option<f64>,
    /// Units per transaction.
    pub expected_units_per_work_transaction: f64,
    /// Parts per unit (0: not known).
    pub number_of_components_per_unit: f64,
    /// The work order.
    pub work_order_identifier: Option<()>,
    /// Boards planned.
    pub target_quantity: Option<f64>,
    /// The surface (`Unspecified`).
    pub relevant_surface: &'static str,
    /// Per stage (none).
    pub recipe_stages_information: Vec<()>,
}

impl RecipeActivated {
    /// The program `recipe_name` selected, with nothing else known (a host protocol that
    /// says only its name).
    pub fn named(recipe_name: impl Into<String>) -> Self {
        Self {
            recipe_name: recipe_name.into(),
            revision: None,
            lane: None,
            stage: None,
            expected_cycle_time: 0.0,
            expected_work_time: None,
            expected_units_per_work_transaction: 1.0,
            number_of_components_per_unit: 0.0,
            work_order_identifier: None,
            target_quantity: None,
            relevant_surface: "Unspecified",
            recipe_stages_information: Vec::new(),
        }
    }
}

/// `CFX.ResourcePerformance.StationOffline`: the machine stopped answering.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StationOffline {}

/// `CFX.ResourcePerformance.StationOnline`: it answers again.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "PascalCase")]
pub struct StationOnline {
    /// How long it was offline (`null`: not known).
    pub offline_duration: Option<TimeSpan>,
}

/// A message body with its name.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// `CFX.EndpointConnected`.
    EndpointConnected(EndpointConnected),
    /// `CFX.EndpointShuttingDown`.
    EndpointShuttingDown(EndpointShuttingDown),
    /// `CFX.Heartbeat`.
    Heartbeat(Heartbeat),
    /// `CFX.AreYouThereResponse`.
    AreYouThereResponse(ThereResponse),
    /// `CFX.WhoIsThereResponse`.
    WhoIsThereResponse(ThereResponse),
    /// `CFX.GetEndpointInformationResponse`.
    GetEndpointInformationResponse(GetEndpointInformationResponse),
    /// `CFX.NotSupportedResponse`.
    NotSupportedResponse(NotSupportedResponse),
    /// `CFX.ResourcePerformance.StationStateChanged`.
    StationStateChanged(StationStateChanged),
    /// `CFX.ResourcePerformance.FaultOccurred`.
    FaultOccurred(FaultOccurred),
    /// `CFX.ResourcePerformance.FaultCleared`.
    FaultCleared(FaultCleared),
    /// `CFX.Production.WorkStarted`.
    WorkStarted(WorkStarted),
    /// `CFX.Production.WorkCompleted`.
    WorkCompleted(WorkCompleted),
    /// `CFX.ResourcePerformance.SMTPlacement.ComponentsPlaced`.
    ComponentsPlaced(ComponentsPlaced),
    /// `CFX.Production.RecipeActivated`.
    RecipeActivated(RecipeActivated),
    /// `CFX.ResourcePerformance.StationOffline`.
    StationOffline(StationOffline),
    /// `CFX.ResourcePerformance.StationOnline`.
    StationOnline(StationOnline),
}

impl Message {
    /// Its full name (`CFX.ResourcePerformance.StationStateChanged`): the envelope's
    /// `MessageName`.
    pub fn name(&self) -> &'static str {
        match self {
            Message::EndpointConnected(_) => "CFX.EndpointConnected",
            Message::EndpointShuttingDown(_) => "CFX.EndpointShuttingDown",
            Message::Heartbeat(_) => "CFX.Heartbeat",
            Message::AreYouThereResponse(_) => "CFX.AreYouThereResponse",
            Message::WhoIsThereResponse(_) => "CFX.WhoIsThereResponse",
            Message::GetEndpointInformationResponse(_) => "CFX.GetEndpointInformationResponse",
            Message::NotSupportedResponse(_) => "CFX.NotSupportedResponse",
            Message::StationStateChanged(_) => "CFX.ResourcePerformance.StationStateChanged",
            Message::FaultOccurred(_) => "CFX.ResourcePerformance.FaultOccurred",
            Message::FaultCleared(_) => "CFX.ResourcePerformance.FaultCleared",
            Message::WorkStarted(_) => "CFX.Production.WorkStarted",
            Message::WorkCompleted(_) => "CFX.Production.WorkCompleted",
            Message::ComponentsPlaced(_) => "CFX.ResourcePerformance.SMTPlacement.ComponentsPlaced",
            Message::RecipeActivated(_) => "CFX.Production.RecipeActivated",
            Message::StationOffline(_) => "CFX.ResourcePerformance.StationOffline",
            Message::StationOnline(_) => "CFX.ResourcePerformance.StationOnline",
        }
    }

    /// Its topic (`CFX.ResourcePerformance`): the name without the last part, AMQP's
    /// `cfx-topic`.
    pub fn topic(&self) -> &'static str {
        let name = self.name();
        name.rsplit_once('.').map_or(name, |(topic, _)| topic)
    }

    /// The body as JSON, `$type` first.
    pub fn body(&self) -> serde_json::Value {
        let fields = match self {
            Message::EndpointConnected(m) => serde_json::to_value(m),
            Message::EndpointShuttingDown(m) => serde_json::to_value(m),
            Message::Heartbeat(m) => serde_json::to_value(m),
            Message::AreYouThereResponse(m) | Message::WhoIsThereResponse(m) => {
                serde_json::to_value(m)
            }
            Message::GetEndpointInformationResponse(m) => serde_json::to_value(m),
            Message::NotSupportedResponse(m) => serde_json::to_value(m),
            Message::StationStateChanged(m) => serde_json::to_value(m),
            Message::FaultOccurred(m) => serde_json::to_value(m),
            Message::FaultCleared(m) => serde_json::to_value(m),
            Message::WorkStarted(m) => serde_json::to_value(m),
            Message::WorkCompleted(m) => serde_json::to_value(m),
            Message::ComponentsPlaced(m) => serde_json::to_value(m),
            Message::RecipeActivated(m) => serde_json::to_value(m),
            Message::StationOffline(m) => serde_json::to_value(m),
            Message::StationOnline(m) => serde_json::to_value(m),
        };
        let mut body = serde_json::Map::new();
        body.insert(
            "$type".to_owned(),
            serde_json::Value::String(format!("{}, CFX", self.name())),
        );
        // Plain data: serialising it cannot fail.
        if let Ok(serde_json::Value::Object(fields)) = fields {
            body.extend(fields);
        }
        serde_json::Value::Object(body)
    }
}
