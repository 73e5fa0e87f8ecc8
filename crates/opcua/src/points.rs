//! The cell's variables made when a client asks for one instead of kept in the address
//! space: a node manager of its own ([`PointNodes`]) that answers Browse,
//! TranslateBrowsePathsToNodeIds, Read, Write, HistoryRead and CreateMonitoredItems for
//! every point variable and its properties (`EngineeringUnits`, `EURange`, `EnumValues`,
//! `EnumStrings`), each device's `Status` and `Error` and each alarm's variables, from the
//! cell's roster, live state and alarm book.
//!
//! Why: async-opcua's in-memory address space keeps each node with its attributes, its
//! value and both directions of every reference in hash maps of their own, about 1.8 kB a
//! point (200 MiB for 100,000 points). Here a variable costs nothing until it is asked
//! for; each answer builds the variable the in-memory space would have held (the same
//! attributes, through async-opcua's own `read_node_value`) and drops it.
//!
//! The objects (the `Cell` folder, lines, devices with their `Production` and `Alarms`
//! folders, alarms, the gateway object, the event type) stay in the in-memory manager
//! ([`crate::nodes`]), which yields these variables to this one
//! ([`crate::items::capped_yielding`]). The two meet at the objects: async-opcua asks
//! every node manager to browse every node, so the in-memory manager gives a device's
//! folders and this one its `Status`, `Error` and points; a browse path is followed by
//! each in turn.
//!
//! Values reach monitored items from the change stream ([`PointTable::notify`]): a point's
//! value is made only when some item monitors it.

use std::collections::VecDeque;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use ::opcua::nodes::{DefaultTypeTree, ReferenceDirection, TypeTree};
use ::opcua::server::address_space::{
    AccessLevel, NodeType, VariableBuilder, read_node_value, validate_node_read,
};
use ::opcua::server::diagnostics::NamespaceMetadata;
use ::opcua::server::node_manager::{
    BrowseNode, BrowsePathItem, ExternalReference, ExternalReferenceRequest, HistoryNode,
    NodeManager, NodeManagerBuilder, NodeMetadata, ReadNode, RequestContext, ServerContext,
    WriteNode,
};
use ::opcua::server::{
    ContinuationPoint, CreateMonitoredItem, SubscriptionCache, node_manager::AddReferenceResult,
};
use ::opcua::types::{
    AttributeId, BrowseDirection, DataTypeId, DataValue, DateTime, ExpandedNodeId, ExtensionObject,
    HistoryData, Identifier, LocalizedText, NodeClass, NodeId, QualifiedName, ReadProcessedDetails,
    ReadRawModifiedDetails, ReferenceDescription, ReferenceTypeId, StatusCode, TimestampsToReturn,
    VariableTypeId, Variant,
};

use super::alarms;
use super::auth::Users;
use super::history::{self, Aggregate, RawRead};
use super::nodes::{self, Caller};
use super::peers::Peers;
use super::space::{self, ids};
use gateway::alarm::book::View as AlarmView;
use gateway::cell::{Cell, DeviceEntry, DeviceSummary, PointView, Roster};
use gateway::point::{PointId, PointKind};
use gateway::time::Timestamp;

/// Which node ids are the variables [`PointNodes`] makes, in the roster and alarm book in
/// force. Shared by [`PointNodes`] and the in-memory manager's wrapper, which leaves these
/// nodes to it.
pub struct PointTable {
    cell: Arc<Cell>,
    /// The cell's namespace, once the in-memory manager has registered it.
    ns: OnceLock<u16>,
}

impl std::fmt::Debug for PointTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointTable").field("ns", &self.ns).finish()
    }
}

/// A property of a point variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Property {
    /// The unit (`EUInformation`), when the point has one.
    EngineeringUnits,
    /// The labels of an enumeration's states (`EnumValueType[]`).
    EnumValues,
    /// The labels when the states are numbered 0, 1, 2, … (`LocalizedText[]`).
    EnumStrings,
    /// The range a numeric point may be written in (`Range`).
    EuRange,
}

impl Property {
    /// Every property, in the order a point's are listed.
    pub const ALL: [Property; 4] = [
        Property::EngineeringUnits,
        Property::EnumValues,
        Property::EnumStrings,
        Property::EuRange,
    ];

    /// Its browse name (in namespace 0, as Part 8 names them).
    pub fn name(self) -> &'static str {
        match self {
            Property::EngineeringUnits => "EngineeringUnits",
            Property::EnumValues => "EnumValues",
            Property::EnumStrings => "EnumStrings",
            Property::EuRange => "EURange",
        }
    }

    fn of_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Whether a point of `spec` has this property.
    fn of(self, spec: &gateway::point::PointDescription) -> bool {
        match (self, &spec.kind) {
            (Property::EngineeringUnits, _) => spec.unit.is_some(),
            (Property::EnumValues, PointKind::Enum { .. }) => true,
            (Property::EnumStrings, PointKind::Enum { states }) => {
                space::enum_strings(states).is_some()
            }
            (Property::EuRange, PointKind::Numeric) => spec.writable.is_some(),
            _ => false,
        }
    }

    /// Its data type and value rank.
    fn data_type(self) -> (DataTypeId, i32) {
        match self {
            Property::EngineeringUnits => (DataTypeId::EUInformation, -1),
            Property::EnumValues => (DataTypeId::EnumValueType, 1),
            Property::EnumStrings => (DataTypeId::LocalizedText, 1),
            Property::EuRange => (DataTypeId::Range, -1),
        }
    }

    /// Its value for a point of `spec` (`Empty` when it has none).
    fn value(self, spec: &gateway::point::PointDescription) -> Variant {
        match (self, &spec.kind) {
            (Property::EngineeringUnits, _) => spec.unit.as_ref().map_or(Variant::Empty, |u| {
                Variant::from(ExtensionObject::from_message(space::eu_information(u)))
            }),
            (Property::EnumValues, PointKind::Enum { states }) => Variant::from(
                space::enum_values(states)
                    .into_iter()
                    .map(ExtensionObject::from_message)
                    .collect::<Vec<_>>(),
            ),
            (Property::EnumStrings, PointKind::Enum { states }) => {
                space::enum_strings(states).map_or(Variant::Empty, Variant::from)
            }
            (Property::EuRange, _) => spec.writable.as_ref().map_or(Variant::Empty, |r| {
                Variant::from(ExtensionObject::from_message(space::eu_range(r)))
            }),
            _ => Variant::Empty,
        }
    }
}

/// A node this manager makes: a point's variable or property, or a read-only variable of
/// an object in the in-memory space (a device's `Status` and `Error`, an alarm's
/// variables).
#[derive(Clone)]
enum Made {
    Point(Found),
    Plain(Plain),
}

/// A read-only variable of an in-memory object; its value is read when asked.
#[derive(Clone)]
enum Plain {
    /// The device's `DEVICE_VARIABLES[index]`.
    Device(Arc<DeviceEntry>, usize),
    /// The alarm's `alarms::VARIABLES[index]`.
    Alarm(Arc<AlarmView>, usize),
}

/// The sampling interval a monitored item of a point gets when the client asks for its
/// poll period or less: the values are set as they are read, one per poll at most, so
/// the item passes every change with the time it was read. (async-opcua, told the poll
/// period, would hold back a change read a little less than one period after the last
/// and restamp it a period after that one.)
pub const EVERY_CHANGE_MS: f64 = 1.0;

/// A device's `Status` and `Error`: name, words (in the order of [`device_values`]).
const DEVICE_VARIABLES: [(&str, &str); 2] = [
    (
        "Status",
        "Whether the device answers: up, down, backed off or connecting",
    ),
    (
        "Error",
        "Why the device is down, or its last refusal (empty when none)",
    ),
];

/// A point's variable or one of its properties.
#[derive(Clone)]
struct Found {
    device: Arc<DeviceEntry>,
    index: usize,
    property: Option<Property>,
}

/// A node whose children this manager makes: a device object or its `Production`
/// folder (points), or an alarm's object (its variables).
enum Parent {
    Device {
        device: Arc<DeviceEntry>,
        production: bool,
    },
    Alarm(Arc<AlarmView>),
}

impl PointTable {
    /// The points of `cell`; the namespace is set by [`PointTable::set_namespace`].
    pub fn new(cell: Arc<Cell>) -> Arc<Self> {
        Arc::new(Self {
            cell,
            ns: OnceLock::new(),
        })
    }

    /// Sets the cell's namespace index (once; later calls are ignored).
    pub fn set_namespace(&self, ns: u16) {
        let _ = self.ns.set(ns);
    }

    /// Whether `id` is a point's variable or property in the roster in force, or a
    /// variable of an alarm in the book.
    pub fn owns(&self, id: &NodeId) -> bool {
        self.find(id).is_some()
    }

    fn find(&self, id: &NodeId) -> Option<Made> {
        match self.find_point(id) {
            Some(found) => Some(Made::Point(found)),
            None => self.find_plain(id).map(Made::Plain),
        }
    }

    fn find_plain(&self, id: &NodeId) -> Option<Plain> {
        let (object, name) = self.text(id)?.rsplit_once('/')?;
        match object.strip_prefix("alarm:") {
            Some(alarm) => {
                let index = alarms::VARIABLES.iter().position(|v| v.0 == name)?;
                let view = self.cell.alarms.view(alarm)?;
                Some(Plain::Alarm(Arc::new(view), index))
            }
            None => {
                let index = DEVICE_VARIABLES.iter().position(|v| v.0 == name)?;
                let device = self.cell.roster().device(object)?.clone();
                Some(Plain::Device(device, index))
            }
        }
    }

    fn text<'a>(&self, id: &'a NodeId) -> Option<&'a str> {
        let ns = *self.ns.get()?;
        match &id.identifier {
            Identifier::String(s) if id.namespace == ns => Some(s.as_ref()),
            _ => None,
        }
    }

    fn find_point(&self, id: &NodeId) -> Option<Found> {
        let text = self.text(id)?;
        let (point, property) = match text.rsplit_once('/') {
            Some((point, name)) => (point, Some(Property::of_name(name)?)),
            None => (text, None),
        };
        let (device, name) = point.split_once('.')?;
        let device = Arc::clone(self.cell.roster().device(device)?);
        let index = device.point_index(name)?;
        if property.is_some_and(|p| !p.of(&device.points[index])) {
            return None;
        }
        Some(Found {
            device,
            index,
            property,
        })
    }

    fn parent(&self, id: &NodeId) -> Option<Parent> {
        let text = self.text(id)?;
        if let Some(alarm) = text.strip_prefix("alarm:") {
            return self
                .cell
                .alarms
                .view(alarm)
                .map(|view| Parent::Alarm(Arc::new(view)));
        }
        let (device, production) = match text.strip_suffix("/Production") {
            Some(device) => (device, true),
            None => (text, false),
        };
        let device = Arc::clone(self.cell.roster().device(device)?);
        Some(Parent::Device { device, production })
    }

    /// Tells the monitored items of a device's `Status` and `Error` its state at `t`.
    pub fn notify_device(
        &self,
        subscriptions: &SubscriptionCache,
        summary: &DeviceSummary,
        t: DateTime,
    ) {
        let Some(&ns) = self.ns.get() else { return };
        let values = device_values(ns, summary, t);
        subscriptions.notify_data_change(
            values
                .iter()
                .map(|(node, value)| (value.clone(), node, AttributeId::Value)),
        );
    }

    /// Tells the monitored items of alarm `view`'s variables its state at `t`.
    pub fn notify_alarm(&self, subscriptions: &SubscriptionCache, view: &AlarmView, t: DateTime) {
        let Some(&ns) = self.ns.get() else { return };
        let values = alarms::values(ns, view, t);
        subscriptions.notify_data_change(
            values
                .iter()
                .map(|(node, value)| (value.clone(), node, AttributeId::Value)),
        );
    }

    /// Tells the monitored items of the point that `view` is read: its value is made only
    /// when some item monitors it.
    pub fn notify(&self, subscriptions: &SubscriptionCache, view: &PointView) {
        let Some(&ns) = self.ns.get() else { return };
        let node = ids::point(ns, view.id.as_str());
        subscriptions.maybe_notify(
            std::iter::once((&node, AttributeId::Value)),
            |_, _, _, _| {
                let spec = self.cell.point(&view.id)?;
                Some(space::data_value(&spec.kind, view, Timestamp::now()))
            },
        );
    }

    /// Tells the monitored items of every variable its value now (after a lag or a
    /// reload): those of the devices of `roster` (the one laid out) and their points, and
    /// those of every alarm.
    pub fn notify_all(&self, subscriptions: &SubscriptionCache, roster: &Roster) {
        let Some(&ns) = self.ns.get() else { return };
        let now = Timestamp::now();
        let t = space::opc_time(now);
        let alarms: Vec<AlarmView> = self
            .cell
            .alarms
            .with(|book| (0..book.len()).filter_map(|i| book.view(i)).collect());
        for view in &alarms {
            self.notify_alarm(subscriptions, view, t);
        }
        for device in roster.devices() {
            self.notify_device(subscriptions, &device.summary(), t);
            let state = device.read();
            for (index, point) in state.points.iter().enumerate() {
                let view = device.point_view(index, point, now);
                let node = ids::point(ns, view.id.as_str());
                let kind = &device.points[index].kind;
                subscriptions.maybe_notify(
                    std::iter::once((&node, AttributeId::Value)),
                    |_, _, _, _| Some(space::data_value(kind, &view, now)),
                );
            }
        }
    }
}

impl Found {
    fn spec(&self) -> &gateway::point::PointSpec {
        &self.device.points[self.index]
    }

    fn point_node(&self, ns: u16) -> NodeId {
        ids::point(ns, self.spec().id.as_str())
    }

    fn node_id(&self, ns: u16) -> NodeId {
        match self.property {
            None => self.point_node(ns),
            Some(p) => ids::property(ns, self.spec().id.as_str(), p.name()),
        }
    }

    /// The node the in-memory space would have held, with its value now.
    fn node(&self, ns: u16) -> NodeType {
        let spec = self.spec();
        let node = self.node_id(ns);
        let variable = match self.property {
            None => {
                let view = {
                    let state = self.device.read();
                    // A device's state has a place for each of its points.
                    let point = &state.points[self.index];
                    self.device.point_view(self.index, point, Timestamp::now())
                };
                let access = self.access();
                let name = spec.id.name();
                let mut variable = VariableBuilder::new(&node, QualifiedName::new(ns, name), name)
                    .description(spec.name.as_ref())
                    .data_type(space::data_type(&spec.kind))
                    .value_rank(-1)
                    .access_level(access)
                    .user_access_level(access)
                    .historizing(true)
                    .minimum_sampling_interval(view.period_ms as f64)
                    .build();
                variable.set_data_value(space::data_value(&spec.kind, &view, Timestamp::now()));
                variable
            }
            Some(property) => {
                let (data_type, rank) = property.data_type();
                let name = property.name();
                let mut variable = VariableBuilder::new(&node, QualifiedName::new(0, name), name)
                    .data_type(data_type)
                    .value_rank(rank)
                    .access_level(AccessLevel::CURRENT_READ)
                    .user_access_level(AccessLevel::CURRENT_READ)
                    .build();
                variable.set_data_value(DataValue::new_now(property.value(spec)));
                variable
            }
        };
        NodeType::Variable(Box::new(variable))
    }

    /// A point's access level: read, history, and write when it is writable.
    fn access(&self) -> AccessLevel {
        let mut access = AccessLevel::CURRENT_READ | AccessLevel::HISTORY_READ;
        if self.spec().writable.is_some() {
            access |= AccessLevel::CURRENT_WRITE;
        }
        access
    }

    fn type_definition(&self) -> VariableTypeId {
        match self.property {
            Some(_) => VariableTypeId::PropertyType,
            None => {
                let spec = self.spec();
                match (&spec.kind, &spec.unit, &spec.writable) {
                    (PointKind::Numeric, _, Some(_)) => VariableTypeId::AnalogItemType,
                    (PointKind::Numeric, Some(_), None) => VariableTypeId::AnalogUnitType,
                    _ => VariableTypeId::BaseDataVariableType,
                }
            }
        }
    }

    fn metadata(&self, ns: u16) -> NodeMetadata {
        let (browse_name, display) = match self.property {
            None => {
                let name = self.spec().id.name();
                (QualifiedName::new(ns, name), name)
            }
            Some(p) => (QualifiedName::new(0, p.name()), p.name()),
        };
        NodeMetadata {
            node_id: self.node_id(ns).into(),
            type_definition: ExpandedNodeId::new(NodeId::from(self.type_definition())),
            browse_name,
            display_name: LocalizedText::from(display),
            node_class: NodeClass::Variable,
        }
    }

    /// The point's properties.
    fn properties(&self) -> impl Iterator<Item = Found> + '_ {
        Property::ALL
            .into_iter()
            .filter(|p| p.of(self.spec()))
            .map(|p| Found {
                property: Some(p),
                ..self.clone()
            })
    }

    /// The node the point hangs under: its device object, or the device's `Production`
    /// folder for the machine state's points.
    fn parent(&self, ns: u16) -> NodeId {
        let device = self.device.id.as_str();
        if gateway::production::is_production_point(self.spec().id.name()) {
            ids::production(ns, device)
        } else {
            ids::device(ns, device)
        }
    }
}

impl Parent {
    /// The nodes of this manager under this node.
    fn children(&self) -> Vec<Made> {
        match self {
            Parent::Device { device, production } => {
                let variables = if *production {
                    0
                } else {
                    DEVICE_VARIABLES.len()
                };
                let variables = (0..variables)
                    .map(|index| Made::Plain(Plain::Device(Arc::clone(device), index)));
                let points = (0..device.points.len())
                    .filter(|&i| {
                        gateway::production::is_production_point(device.points[i].id.name())
                            == *production
                    })
                    .map(|index| {
                        Made::Point(Found {
                            device: Arc::clone(device),
                            index,
                            property: None,
                        })
                    });
                variables.chain(points).collect()
            }
            Parent::Alarm(view) => (0..alarms::VARIABLES.len())
                .map(|index| Made::Plain(Plain::Alarm(Arc::clone(view), index)))
                .collect(),
        }
    }
}

/// The values of a device's `Status` and `Error` ([`DEVICE_VARIABLES`]) at `t`.
fn device_values(ns: u16, summary: &DeviceSummary, t: DateTime) -> [(NodeId, DataValue); 2] {
    let id = summary.id.as_str();
    [
        (
            ids::device_status(ns, id),
            DataValue::new_at(space::device_status(summary), t),
        ),
        (
            ids::device_error(ns, id),
            DataValue::new_at(space::device_error(summary), t),
        ),
    ]
}

impl Plain {
    fn name(&self) -> &'static str {
        match self {
            Plain::Device(_, index) => DEVICE_VARIABLES[*index].0,
            Plain::Alarm(_, index) => alarms::VARIABLES[*index].0,
        }
    }

    fn node_id(&self, ns: u16) -> NodeId {
        match self {
            Plain::Device(device, 0) => ids::device_status(ns, device.id.as_str()),
            Plain::Device(device, _) => ids::device_error(ns, device.id.as_str()),
            Plain::Alarm(view, _) => ids::alarm_variable(ns, &view.id, self.name()),
        }
    }

    /// The object it is a component of.
    fn parent(&self, ns: u16) -> NodeId {
        match self {
            Plain::Device(device, _) => ids::device(ns, device.id.as_str()),
            Plain::Alarm(view, _) => ids::alarm(ns, &view.id),
        }
    }

    /// Its value now: a device's timed when its status began.
    fn value(&self, ns: u16) -> DataValue {
        let values = match self {
            Plain::Device(device, _) => {
                let summary = device.summary();
                device_values(ns, &summary, space::opc_time(summary.since)).to_vec()
            }
            Plain::Alarm(view, _) => alarms::values(ns, view, DateTime::now()),
        };
        let (Plain::Device(_, index) | Plain::Alarm(_, index)) = self;
        values
            .into_iter()
            .nth(*index)
            .map_or_else(DataValue::null, |(_, value)| value)
    }

    /// The variable as the in-memory space would hold it.
    fn node(&self, ns: u16) -> NodeType {
        let (name, data_type, words) = match self {
            Plain::Device(_, index) => {
                let (name, words) = DEVICE_VARIABLES[*index];
                (name, DataTypeId::String, words)
            }
            Plain::Alarm(_, index) => alarms::VARIABLES[*index],
        };
        let mut variable =
            VariableBuilder::new(&self.node_id(ns), QualifiedName::new(ns, name), name)
                .description(words)
                .data_type(data_type)
                .value_rank(-1)
                .access_level(AccessLevel::CURRENT_READ)
                .user_access_level(AccessLevel::CURRENT_READ)
                .build();
        variable.set_data_value(self.value(ns));
        NodeType::Variable(Box::new(variable))
    }

    fn metadata(&self, ns: u16) -> NodeMetadata {
        NodeMetadata {
            node_id: self.node_id(ns).into(),
            type_definition: ExpandedNodeId::new(NodeId::from(
                VariableTypeId::BaseDataVariableType,
            )),
            browse_name: QualifiedName::new(ns, self.name()),
            display_name: LocalizedText::from(self.name()),
            node_class: NodeClass::Variable,
        }
    }
}

impl Made {
    fn node(&self, ns: u16) -> NodeType {
        match self {
            Made::Point(found) => found.node(ns),
            Made::Plain(variable) => variable.node(ns),
        }
    }

    fn metadata(&self, ns: u16) -> NodeMetadata {
        match self {
            Made::Point(found) => found.metadata(ns),
            Made::Plain(variable) => variable.metadata(ns),
        }
    }
}

/// A reference from a node of this manager (or to one, from a device object).
enum Reference {
    /// To a node of this manager.
    Own(ReferenceTypeId, bool, Made),
    /// To a node of another manager (a type definition, a device object).
    Other(ReferenceTypeId, bool, NodeId),
}

/// What is left of a browse when the client's page was full.
struct Rest(VecDeque<ReferenceDescription>);

/// The node manager of the points ([`PointTable`]).
pub struct PointNodes {
    table: Arc<PointTable>,
    users: Users,
    peers: Arc<Peers>,
}

/// The builder the server takes, after the in-memory manager of the cell (which sets
/// the namespace).
pub fn builder(table: Arc<PointTable>, users: Users, peers: Arc<Peers>) -> impl NodeManagerBuilder {
    move |_context: ServerContext| PointNodes {
        table,
        users,
        peers,
    }
}

impl PointNodes {
    fn ns(&self) -> u16 {
        self.table.ns.get().copied().unwrap_or_default()
    }

    /// The references of `id` (in `direction`), if it is a node this manager knows of or
    /// a device object or `Production` folder with points.
    fn references(&self, id: &NodeId, direction: BrowseDirection) -> Vec<Reference> {
        let ns = self.ns();
        let forward = matches!(direction, BrowseDirection::Forward | BrowseDirection::Both);
        let inverse = matches!(direction, BrowseDirection::Inverse | BrowseDirection::Both);
        let mut refs = Vec::new();
        match self.table.find(id) {
            Some(Made::Plain(variable)) => {
                if forward {
                    refs.push(Reference::Other(
                        ReferenceTypeId::HasTypeDefinition,
                        true,
                        VariableTypeId::BaseDataVariableType.into(),
                    ));
                }
                if inverse {
                    refs.push(Reference::Other(
                        ReferenceTypeId::HasComponent,
                        false,
                        variable.parent(ns),
                    ));
                }
            }
            Some(Made::Point(found)) => {
                if forward {
                    refs.push(Reference::Other(
                        ReferenceTypeId::HasTypeDefinition,
                        true,
                        found.type_definition().into(),
                    ));
                    if found.property.is_none() {
                        refs.extend(found.properties().map(|p| {
                            Reference::Own(ReferenceTypeId::HasProperty, true, Made::Point(p))
                        }));
                    }
                }
                if inverse {
                    refs.push(match found.property {
                        None => {
                            Reference::Other(ReferenceTypeId::HasComponent, false, found.parent(ns))
                        }
                        Some(_) => Reference::Own(
                            ReferenceTypeId::HasProperty,
                            false,
                            Made::Point(Found {
                                property: None,
                                ..found
                            }),
                        ),
                    });
                }
            }
            None => {
                if forward && let Some(parent) = self.table.parent(id) {
                    refs.extend(
                        parent.children().into_iter().map(|child| {
                            Reference::Own(ReferenceTypeId::HasComponent, true, child)
                        }),
                    );
                }
            }
        }
        refs
    }

    fn browse_one(&self, types: &DefaultTypeTree, node: &mut BrowseNode) {
        let ns = self.ns();
        let mut rest = match node.take_continuation_point::<Rest>() {
            Some(rest) => rest.0,
            None => {
                let mut rest = VecDeque::new();
                for reference in self.references(node.node_id(), node.browse_direction()) {
                    match reference {
                        Reference::Own(kind, forward, found) => {
                            let description = found.metadata(ns).into_ref_desc(forward, kind);
                            if node.matches_filter(types, &description) {
                                rest.push_back(description);
                            }
                        }
                        Reference::Other(kind, forward, target) => {
                            node.push_external_reference(ExternalReference::new(
                                target.into(),
                                kind.into(),
                                if forward {
                                    ReferenceDirection::Forward
                                } else {
                                    ReferenceDirection::Inverse
                                },
                            ));
                        }
                    }
                }
                rest
            }
        };
        while let Some(description) = rest.pop_front() {
            if let AddReferenceResult::Full(description) = node.add(types, description) {
                rest.push_front(description);
                break;
            }
        }
        if !rest.is_empty() {
            node.set_next_continuation_point(Box::new(Rest(rest)));
        }
    }

    /// Follows `item`'s path through this manager's references, adding every node reached
    /// at each depth (async-opcua goes on from them through the other managers).
    fn translate_one(&self, types: &DefaultTypeTree, item: &mut BrowsePathItem) {
        let ns = self.ns();
        let mut reached = vec![item.node_id().clone()];
        let mut depth = 0;
        for element in item.path() {
            depth += 1;
            let direction = if element.is_inverse {
                BrowseDirection::Inverse
            } else {
                BrowseDirection::Forward
            };
            let mut next = Vec::new();
            for node in &reached {
                for reference in self.references(node, direction) {
                    let Reference::Own(kind, _, found) = reference else {
                        continue;
                    };
                    let kind: NodeId = kind.into();
                    let allowed = element.reference_type_id.is_null()
                        || kind == element.reference_type_id
                        || element.include_subtypes
                            && types.is_subtype_of(&kind, &element.reference_type_id);
                    let meta = found.metadata(ns);
                    if allowed
                        && (element.target_name.is_null()
                            || meta.browse_name == element.target_name)
                    {
                        next.push(meta.node_id.node_id);
                    }
                }
            }
            for node in &next {
                item.add_element(node.clone(), depth, None);
            }
            if next.is_empty() {
                break;
            }
            reached = next;
        }
    }

    fn point_of(&self, node: &NodeId) -> Option<(PointId, PointKind)> {
        let found = self.table.find_point(node)?;
        if found.property.is_some() {
            return None;
        }
        let spec = found.spec();
        Some((spec.id.clone(), spec.kind.clone()))
    }

    /// The point of a history node, or why it has no history.
    fn history_point(
        &self,
        context: &RequestContext,
        node: &HistoryNode,
    ) -> Result<(PointId, PointKind), StatusCode> {
        let found = match self.table.find(node.node_id()) {
            Some(Made::Point(found)) if found.property.is_none() => found,
            // A property or an alarm's variable: no history.
            Some(_) => return Err(StatusCode::BadUserAccessDenied),
            None => return Err(StatusCode::BadNodeIdUnknown),
        };
        let access = context.authenticator.effective_user_access_level(
            &context.token,
            found.access(),
            node.node_id(),
        );
        if !access.contains(AccessLevel::HISTORY_READ) {
            return Err(StatusCode::BadUserAccessDenied);
        }
        let spec = found.spec();
        Ok((spec.id.clone(), spec.kind.clone()))
    }
}

#[async_trait::async_trait]
impl NodeManager for PointNodes {
    fn owns_node(&self, id: &NodeId) -> bool {
        self.table.owns(id)
    }

    fn name(&self) -> &str {
        "cellbus points"
    }

    /// The namespace is the cell's, which its in-memory manager names.
    fn namespaces_for_user(&self, _context: &RequestContext) -> Vec<NamespaceMetadata> {
        Vec::new()
    }

    async fn init(&self, _type_tree: &mut DefaultTypeTree, _context: ServerContext) {}

    async fn resolve_external_references(
        &self,
        _context: &RequestContext,
        items: &mut [&mut ExternalReferenceRequest],
    ) {
        let ns = self.ns();
        for item in items.iter_mut() {
            if let Some(found) = self.table.find(item.node_id()) {
                item.set(found.metadata(ns));
            }
        }
    }

    async fn browse(
        &self,
        context: &RequestContext,
        nodes_to_browse: &mut [BrowseNode],
    ) -> Result<(), StatusCode> {
        let types = context.type_tree.read();
        for node in nodes_to_browse.iter_mut() {
            if self.table.text(node.node_id()).is_some() {
                self.browse_one(&types, node);
            }
        }
        Ok(())
    }

    async fn translate_browse_paths_to_node_ids(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut BrowsePathItem],
    ) -> Result<(), StatusCode> {
        let types = context.type_tree.read();
        for item in nodes.iter_mut() {
            if self.table.text(item.node_id()).is_some() {
                self.translate_one(&types, item);
            }
        }
        Ok(())
    }

    async fn read(
        &self,
        context: &RequestContext,
        max_age: f64,
        timestamps_to_return: TimestampsToReturn,
        nodes_to_read: &mut [&mut ReadNode],
    ) -> Result<(), StatusCode> {
        let ns = self.ns();
        for read in nodes_to_read.iter_mut() {
            let Some(found) = self.table.find(&read.node().node_id) else {
                read.set_error(StatusCode::BadNodeIdUnknown);
                continue;
            };
            let node = found.node(ns);
            match validate_node_read(&node, context, read.node()) {
                Ok(()) => {
                    let value =
                        read_node_value(&node, context, read.node(), max_age, timestamps_to_return);
                    read.set_result(value);
                }
                Err(status) => read.set_error(status),
            }
        }
        Ok(())
    }

    async fn write(
        &self,
        context: &RequestContext,
        nodes_to_write: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        let client = Caller::of(context, &self.peers).client();
        for node in nodes_to_write.iter_mut() {
            let status = match self.point_of(&node.value().node_id) {
                Some(point) => {
                    nodes::write_one(
                        &self.table.cell,
                        &self.users,
                        context,
                        &client,
                        point,
                        node.value(),
                    )
                    .await
                }
                // A property, a device's `Status` or `Error`, an alarm's variable.
                None => StatusCode::BadNotWritable,
            };
            node.set_status(status);
        }
        Ok(())
    }

    async fn history_read_raw_modified(
        &self,
        context: &RequestContext,
        details: &ReadRawModifiedDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        if details.is_read_modified {
            return Err(StatusCode::BadHistoryOperationUnsupported);
        }
        if timestamps == TimestampsToReturn::Neither {
            return Err(StatusCode::BadTimestampsToReturnInvalid);
        }
        let asked = RawRead::new(
            history::TimeRange::of(&details.start_time, &details.end_time, Timestamp::now()),
            details.num_values_per_node,
            details.return_bounds,
        );
        for node in nodes.iter_mut() {
            let (point, kind) = match self.history_point(context, node) {
                Ok(point) => point,
                Err(status) => {
                    node.set_status(status);
                    continue;
                }
            };
            // A continuation point carries the read as the first call asked it, and the
            // point it was for: another node's is refused.
            let read = match node.continuation_point() {
                None => asked.clone(),
                Some(continued) => match continued.get::<(PointId, RawRead)>() {
                    Some((of, read)) if *of == point => read.clone(),
                    _ => {
                        node.set_status(StatusCode::BadContinuationPointInvalid);
                        continue;
                    }
                },
            };
            match nodes::fetch_raw(&self.table.cell, point.clone(), &read).await {
                Ok(fetched) => {
                    let (values, more) = read.page(&kind, fetched);
                    node.set_result(HistoryData {
                        data_values: Some(history::with_timestamps(values, timestamps)),
                    });
                    node.set_next_continuation_point(
                        more.map(|read| ContinuationPoint::new(Box::new((point.clone(), read)))),
                    );
                    node.set_status(StatusCode::Good);
                }
                Err(status) => node.set_status(status),
            }
        }
        Ok(())
    }

    async fn history_read_processed(
        &self,
        context: &RequestContext,
        details: &ReadProcessedDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        if timestamps == TimestampsToReturn::Neither {
            return Err(StatusCode::BadTimestampsToReturnInvalid);
        }
        let range =
            history::TimeRange::of(&details.start_time, &details.end_time, Timestamp::now());
        let milliseconds = details.processing_interval;
        let interval = (milliseconds.is_finite() && milliseconds >= 0.0)
            .then(|| Duration::try_from_secs_f64(milliseconds / 1000.0).ok())
            .flatten();
        let aggregates = details.aggregate_type.clone().unwrap_or_default();
        let chosen = match nodes::aggregates_of(&aggregates, nodes.len()) {
            Ok(chosen) => chosen,
            Err(status) => {
                for node in nodes.iter_mut() {
                    node.set_status(status);
                }
                return Ok(());
            }
        };
        for (node, aggregate) in nodes.iter_mut().zip(chosen) {
            let Some(aggregate) = aggregate.and_then(Aggregate::of) else {
                node.set_status(StatusCode::BadAggregateNotSupported);
                continue;
            };
            let Some(interval) = interval else {
                node.set_status(StatusCode::BadAggregateInvalidInputs);
                continue;
            };
            let (point, kind) = match self.history_point(context, node) {
                Ok(point) => point,
                Err(status) => {
                    node.set_status(status);
                    continue;
                }
            };
            if !matches!(kind, PointKind::Numeric) {
                node.set_status(StatusCode::BadAggregateInvalidInputs);
                continue;
            }
            let Some(step) = history::check_interval(range, interval) else {
                node.set_status(StatusCode::BadAggregateInvalidInputs);
                continue;
            };
            match nodes::read_history(&self.table.cell, point, range, None).await {
                Ok(stored) => {
                    let values = history::processed(&stored, range, step, aggregate);
                    node.set_result(HistoryData {
                        data_values: Some(history::with_timestamps(values, timestamps)),
                    });
                    node.set_status(StatusCode::Good);
                }
                Err(status) => node.set_status(status),
            }
        }
        Ok(())
    }

    /// Each item gets the node's value now; a point's value item asked to sample at its
    /// poll period or faster gets [`EVERY_CHANGE_MS`]. Values come from
    /// [`PointTable::notify`]. A variable has no events to subscribe to.
    async fn create_monitored_items(
        &self,
        context: &RequestContext,
        items: &mut [&mut CreateMonitoredItem],
    ) -> Result<(), StatusCode> {
        let ns = self.ns();
        for item in items.iter_mut() {
            let Some(found) = self.table.find(&item.item_to_monitor().node_id) else {
                item.set_status(StatusCode::BadNodeIdUnknown);
                continue;
            };
            let node = found.node(ns);
            if let Err(status) = validate_node_read(&node, context, item.item_to_monitor()) {
                item.set_status(status);
                continue;
            }
            let attribute = item.item_to_monitor().attribute_id;
            if attribute == AttributeId::EventNotifier {
                item.set_status(StatusCode::BadAttributeIdInvalid);
                continue;
            }
            let value = read_node_value(
                &node,
                context,
                item.item_to_monitor(),
                0.0,
                item.timestamps_to_return(),
            );
            if value.status() != StatusCode::BadAttributeIdInvalid {
                item.set_initial_value(value);
            }
            item.set_status(StatusCode::Good);
            let asked = item.sampling_interval();
            if let Made::Point(point) = &found
                && attribute == AttributeId::Value
                && point.property.is_none()
                && asked >= 0.0
                && asked <= point.device.period(&point.spec().group).as_secs_f64() * 1000.0
            {
                item.revise_sampling_interval(EVERY_CHANGE_MS);
            }
        }
        Ok(())
    }
}
