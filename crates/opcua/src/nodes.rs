//! The cell's in-memory node manager: builds `Objects/Cell/{line}/{device}` (each device's
//! `Production` and `Alarms` folders and its alarms' objects) and the gateway object (device objects and
//! the gateway object notify events), and calls the alarm methods. The points under the
//! devices are [`crate::points`]'s; the writes and history reads of points, which that
//! manager answers, are here too ([`write_one`], [`fetch_raw`], [`read_history`]).

use std::sync::Arc;
use std::time::Duration;

use ::opcua::nodes::TypeTree;
use ::opcua::server::CreateMonitoredItem;
use ::opcua::server::address_space::{
    AccessLevel, AddressSpace, EventNotifier, MethodBuilder, NodeType, ObjectBuilder,
    ObjectTypeBuilder, VariableBuilder,
};
use ::opcua::server::diagnostics::NamespaceMetadata;
use ::opcua::server::node_manager::memory::{
    InMemoryNodeManager, InMemoryNodeManagerBuilder, InMemoryNodeManagerImpl,
};
use ::opcua::server::node_manager::{
    MethodCall, NodeManagerBuilder, ParsedReadValueId, RequestContext, ServerContext, WriteNode,
};
use ::opcua::sync::RwLock;
use ::opcua::types::{
    AttributeId, BrowseDirection, DataTypeId, DataValue, LocalizedText, NodeId, NumericRange,
    ObjectId, ObjectTypeId, QualifiedName, ReferenceTypeId, StatusCode, TimestampsToReturn,
    VariableTypeId, Variant,
};

use super::alarms::{self, BadArguments, Method};
use super::auth::Users;
use super::history::{self, Fetched, RawRead};
use super::peers::Peers;
use super::points::PointTable;
use super::space::{self, ids};
use gateway::alarm::book::View as AlarmView;
use gateway::cell::{Cell, DeviceEntry, Roster};
use gateway::driver::{ErrorKind, WriteError};
use gateway::point::{DeviceId, PointId, PointKind, ValueError};
use gateway::write::Attempt;

/// The node manager of the cell.
pub type CellManager = InMemoryNodeManager<CellNodes>;

/// The cell's nodes: what the address space holds and how to reach the cell.
pub struct CellNodes {
    cell: Arc<Cell>,
    users: Users,
    peers: Arc<Peers>,
    ns: u16,
}

/// The builder the server takes: registers the namespace (and tells `points` its index)
/// and builds the nodes.
pub fn builder(
    cell: Arc<Cell>,
    users: Users,
    peers: Arc<Peers>,
    points: Arc<PointTable>,
) -> impl NodeManagerBuilder {
    InMemoryNodeManagerBuilder::new(move |context: ServerContext, space: &mut AddressSpace| {
        let ns = context
            .type_tree
            .write()
            .namespaces_mut()
            .add_namespace(space::NAMESPACE_URI);
        space.add_namespace(space::NAMESPACE_URI, ns);
        points.set_namespace(ns);
        let types = context.type_tree.read();
        build(space, &*types, ns, &cell);
        CellNodes {
            cell,
            users,
            peers,
            ns,
        }
    })
}

impl CellNodes {
    /// The namespace index of the cell's nodes.
    pub fn namespace(&self) -> u16 {
        self.ns
    }

    /// Brings `Objects/Cell` to `roster` after a reload replaced the one it was laid out
    /// from (see [`lay_out`]), with `changed` the devices whose table the reload changed;
    /// keeps the point variables' table in step. `types` is the server's type tree.
    ///
    /// Monitored items on the nodes removed stay: async-opcua 0.19 keeps them in its
    /// `SubscriptionCache` by node id and attribute whatever the address space holds (its
    /// own DeleteNodes does not touch them either), with their last value and no new
    /// status, until the client deletes them or its subscription ends; they are counted in
    /// [`crate::items`] until then. An item on a node built again under the same id (a
    /// changed device's points) is notified again, since values are set by node id.
    /// Clients learn of the change by the `config_reloaded` event (a `CellbusEventType` of
    /// the Gateway object) and browse again: no GeneralModelChangeEvent, which async-opcua
    /// has only as a node id, with no event type or server side to raise it.
    pub fn follow_roster(
        &self,
        space: &mut AddressSpace,
        types: &dyn TypeTree,
        roster: &Roster,
        changed: &[DeviceId],
    ) {
        lay_out(space, types, self.ns, &self.cell, roster, changed);
    }
}

/// Builds the cell's nodes.
fn build(space: &mut AddressSpace, types: &dyn TypeTree, ns: u16, cell: &Cell) {
    ObjectBuilder::new(&ids::cell(ns), QualifiedName::new(ns, "Cell"), "Cell")
        .description("The production cell: a folder per line, an object per device")
        .is_folder()
        .organized_by(ObjectId::ObjectsFolder)
        .insert(space);
    lay_out(space, types, ns, cell, &cell.roster(), &[]);
    build_gateway(space, ns, cell);
    build_event_type(space, ns);
}

/// Lays `Objects/Cell` out as `roster` has it, the one path of the start (an empty
/// folder) and of a reload: removes each device object (with all under it: points and
/// their properties, `Status`, `Error`, `Production`, `Alarms` and the alarms' objects)
/// that `roster` does not have, has on another line or that is in `changed`, and each
/// line folder of a line it does not have; then adds a folder for each new line and
/// builds each device that has no object (with its alarms), and makes each remaining
/// device's `Alarms` folder hold its alarms of the book again if the reload changed them.
/// (The points are not in the address space: [`crate::points`] follows the roster.)
///
/// The devices added and removed are read from the address space against `roster`, not
/// from the reload's event: the same answer, and one that holds after a lag too.
fn lay_out(
    space: &mut AddressSpace,
    types: &dyn TypeTree,
    ns: u16,
    cell: &Cell,
    roster: &Roster,
    changed: &[DeviceId],
) {
    let cell_id = ids::cell(ns);
    let lines: Vec<NodeId> = children(space, types, ns, &cell_id, ReferenceTypeId::Organizes);
    // Device objects that stay: on the folder of their line, and not changed.
    for line in &lines {
        for device in children(space, types, ns, line, ReferenceTypeId::Organizes) {
            let stays = roster.devices().any(|d| {
                ids::device(ns, d.id.as_str()) == device
                    && ids::line(ns, &d.line) == *line
                    && !changed.contains(&d.id)
            });
            if !stays {
                remove_tree(space, types, ns, &device);
            }
        }
    }
    for line in &lines {
        if !roster
            .lines()
            .iter()
            .any(|l| ids::line(ns, &l.name) == *line)
        {
            remove_tree(space, types, ns, line);
        }
    }
    let alarms: Vec<AlarmView> = cell
        .alarms
        .with(|book| (0..book.len()).filter_map(|i| book.view(i)).collect());
    let of_device = |device: &DeviceId| -> Vec<&AlarmView> {
        alarms.iter().filter(|a| a.device == *device).collect()
    };
    for line in roster.lines() {
        let line_id = ids::line(ns, &line.name);
        let description = format!("Line {} on {}", line.name, line.endpoint);
        match space.find_mut(&line_id) {
            // A line restarted on another endpoint keeps its folder.
            Some(folder) => folder
                .as_mut_node()
                .set_description(LocalizedText::from(description.as_str())),
            None => {
                ObjectBuilder::new(&line_id, QualifiedName::new(ns, &line.name), &line.name)
                    .description(description)
                    .is_folder()
                    .organized_by(cell_id.clone())
                    .insert(space);
            }
        }
        for device in roster.devices().filter(|d| d.line == line.name) {
            let id = device.id.as_str();
            let views = of_device(&device.id);
            if space.node_exists(&ids::device(ns, id)) {
                keep_alarms(space, types, ns, id, &views);
            } else {
                build_device(space, ns, &line_id, device);
                build_alarms(space, ns, id, &views);
            }
        }
    }
}

/// Makes the existing `Alarms` folder of `device` hold the objects of `views`, built again
/// when they differ (the alarms of a device a reload did not change, whose rules did).
fn keep_alarms(
    space: &mut AddressSpace,
    types: &dyn TypeTree,
    ns: u16,
    device: &str,
    views: &[&AlarmView],
) {
    let folder = ids::device_alarms(ns, device);
    let mut present = children(space, types, ns, &folder, ReferenceTypeId::Organizes);
    let mut wanted: Vec<NodeId> = views.iter().map(|v| ids::alarm(ns, &v.id)).collect();
    present.sort_by_key(ToString::to_string);
    wanted.sort_by_key(ToString::to_string);
    if present != wanted {
        remove_tree(space, types, ns, &folder);
        build_alarms(space, ns, device, views);
    }
}

/// The targets of `node`'s forward references of type `reference` (or a subtype) in the
/// namespace `ns`.
fn children(
    space: &AddressSpace,
    types: &dyn TypeTree,
    ns: u16,
    node: &NodeId,
    reference: ReferenceTypeId,
) -> Vec<NodeId> {
    space
        .find_references(
            node,
            Some((reference, true)),
            types,
            BrowseDirection::Forward,
        )
        .filter(|r| r.target_node.namespace == ns)
        .map(|r| r.target_node.clone())
        .collect()
}

/// Deletes `root` and every node of the namespace `ns` under it (forward hierarchical
/// references: Organizes, HasComponent, HasProperty), each with every reference from and
/// to it (the parent's to it, the type definition's inverse); returns the nodes deleted.
fn remove_tree(
    space: &mut AddressSpace,
    types: &dyn TypeTree,
    ns: u16,
    root: &NodeId,
) -> Vec<NodeId> {
    let mut deleted = Vec::new();
    let mut to_delete = vec![root.clone()];
    while let Some(node) = to_delete.pop() {
        to_delete.extend(children(
            space,
            types,
            ns,
            &node,
            ReferenceTypeId::HierarchicalReferences,
        ));
        if space.delete(&node, true).is_some() {
            deleted.push(node);
        }
    }
    deleted
}

/// `CellbusEventType`, the type of the gateway's events ([`space::CellEvent`]): a
/// BaseEventType with `Kind` and `Fields`, so a client finds both by browsing the type and
/// selects them in its event filter.
fn build_event_type(space: &mut AddressSpace, ns: u16) {
    let event_type = NodeId::new(ns, space::EVENT_TYPE);
    ObjectTypeBuilder::new(
        &event_type,
        QualifiedName::new(ns, space::EVENT_TYPE),
        space::EVENT_TYPE,
    )
    .description(
        "An event of the cell: its kind as /api/events names it and its fields for programs \
         (JSON)",
    )
    .is_abstract(false)
    .subtype_of(ObjectTypeId::BaseEventType)
    .insert(space);
    for (name, words) in [
        (
            "Kind",
            "The event's kind: write, device_event, state_changed, alarm_raised, …",
        ),
        (
            "Fields",
            "The event's facts for programs, a JSON object (the feeder that ran out, the \
             value written, the state a transfer switch went to)",
        ),
    ] {
        VariableBuilder::new(
            &NodeId::new(ns, format!("{}.{name}", space::EVENT_TYPE)),
            QualifiedName::new(ns, name),
            name,
        )
        .description(words)
        .data_type(DataTypeId::String)
        .value_rank(-1)
        .has_type_definition(VariableTypeId::PropertyType)
        .has_modelling_rule(ObjectId::ModellingRule_Mandatory)
        .property_of(event_type.clone())
        .insert(space);
    }
}

fn build_device(space: &mut AddressSpace, ns: u16, line_id: &NodeId, device: &DeviceEntry) {
    let id = device.id.as_str();
    let device_id = ids::device(ns, id);
    ObjectBuilder::new(&device_id, QualifiedName::new(ns, id), id)
        .description(device.name.as_str())
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .organized_by(line_id.clone())
        .insert(space);
    // Its `Status` and `Error` and its points are `crate::points`'. The machine state and
    // the OEE go in a `Production` folder, when the device has them.
    if device
        .points
        .iter()
        .any(|p| gateway::production::is_production_point(p.id.name()))
    {
        ObjectBuilder::new(
            &ids::production(ns, id),
            QualifiedName::new(ns, "Production"),
            "Production",
        )
        .description(
            "The device's machine state on the SEMI E10 scale (its word, its IPC-CFX code, its \
             reason) and, for a device that counts production, the OEE of the shift under way",
        )
        .is_folder()
        .component_of(device_id.clone())
        .insert(space);
    }
}

/// A device's `Alarms` folder: an object per alarm, named by its id (its state's variables,
/// [`alarms::VARIABLES`], are [`crate::points`]').
fn build_alarms(space: &mut AddressSpace, ns: u16, device: &str, views: &[&AlarmView]) {
    if views.is_empty() {
        return;
    }
    let folder = ids::device_alarms(ns, device);
    ObjectBuilder::new(&folder, QualifiedName::new(ns, "Alarms"), "Alarms")
        .description(
            "The device's alarms (ISA-18.2), an object each named by its id; \
             Objects/Gateway/Alarms acknowledges and shelves them",
        )
        .is_folder()
        .component_of(ids::device(ns, device))
        .insert(space);
    for view in views {
        // Its variables (`alarms::VARIABLES`) are `crate::points`', made when asked.
        ObjectBuilder::new(
            &ids::alarm(ns, &view.id),
            QualifiedName::new(ns, &view.id),
            &view.id,
        )
        .description(view.message.as_str())
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .organized_by(folder.clone())
        .insert(space);
    }
}

/// `Objects/Gateway/Alarms`: the methods that act on alarms ([`alarms::Method`]).
fn build_alarm_methods(space: &mut AddressSpace, ns: u16) {
    let object = ids::alarm_methods(ns);
    ObjectBuilder::new(&object, QualifiedName::new(ns, "Alarms"), "Alarms")
        .description(
            "Acknowledge, Shelve and Unshelve the cell's alarms by id, as the OPC UA user \
             (who may write)",
        )
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .component_of(ids::gateway(ns, None))
        .insert(space);
    for method in Method::ALL {
        let name = method.name();
        let node = ids::alarm_method(ns, name);
        MethodBuilder::new(&node, QualifiedName::new(ns, name), name)
            .description(method.words())
            .component_of(object.clone())
            .executable(true)
            .user_executable(true)
            .input_args(
                space,
                &ids::alarm_method_arguments(ns, name, "InputArguments"),
                &method.inputs(),
            )
            .output_args(
                space,
                &ids::alarm_method_arguments(ns, name, "OutputArguments"),
                &Method::outputs(),
            )
            .insert(space);
    }
}

/// The gateway object: its version, its lines and the history rows written.
fn build_gateway(space: &mut AddressSpace, ns: u16, cell: &Cell) {
    let gateway = ids::gateway(ns, None);
    ObjectBuilder::new(&gateway, QualifiedName::new(ns, "Gateway"), "Gateway")
        .description("The cellbus gateway serving this cell")
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .organized_by(ObjectId::ObjectsFolder)
        .insert(space);
    let variables: [(&str, &str, DataTypeId, i32, Variant); 3] = [
        (
            "Version",
            "The gateway's version",
            DataTypeId::String,
            -1,
            Variant::from(env!("CARGO_PKG_VERSION")),
        ),
        (
            LINES,
            "The names of the lines the gateway polls",
            DataTypeId::String,
            1,
            line_names(&cell.roster()),
        ),
        (
            HISTORY_ROWS,
            "History rows written since the gateway started",
            DataTypeId::UInt64,
            -1,
            Variant::UInt64(cell.store().stats().rows_written()),
        ),
    ];
    for (name, words, data_type, rank, value) in variables {
        let node = ids::gateway(ns, Some(name));
        VariableBuilder::new(&node, QualifiedName::new(ns, name), name)
            .description(words)
            .data_type(data_type)
            .value_rank(rank)
            .access_level(AccessLevel::CURRENT_READ)
            .user_access_level(AccessLevel::CURRENT_READ)
            .has_type_definition(VariableTypeId::BaseDataVariableType)
            .component_of(gateway.clone())
            .insert(space);
        set(space, &node, DataValue::new_now(value));
    }
    build_alarm_methods(space, ns);
}

/// The gateway variable counting history rows.
pub const HISTORY_ROWS: &str = "HistoryRows";

/// The gateway variable naming the lines.
pub const LINES: &str = "Lines";

/// The value of the gateway's [`LINES`] for `roster`: its lines' names.
pub fn line_names(roster: &Roster) -> Variant {
    let names: Vec<String> = roster.lines().iter().map(|l| l.name.clone()).collect();
    Variant::from(names)
}

fn set(space: &mut AddressSpace, node: &NodeId, value: DataValue) {
    if let Some(NodeType::Variable(variable)) = space.find_mut(node) {
        variable.set_data_value(value);
    }
}

#[async_trait::async_trait]
impl InMemoryNodeManagerImpl for CellNodes {
    async fn init(&self, _space: &mut AddressSpace, _context: ServerContext) {}

    fn name(&self) -> &str {
        "cellbus"
    }

    fn namespaces(&self) -> Vec<NamespaceMetadata> {
        vec![NamespaceMetadata {
            namespace_uri: space::NAMESPACE_URI.to_owned(),
            namespace_index: self.ns,
            ..NamespaceMetadata::default()
        }]
    }

    async fn write(
        &self,
        context: &RequestContext,
        space: &RwLock<AddressSpace>,
        nodes_to_write: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        // The points, which are written, are `crate::points`'.
        let _ = context;
        for node in nodes_to_write {
            let exists = space.read().node_exists(&node.value().node_id);
            node.set_status(if exists {
                StatusCode::BadNotWritable
            } else {
                StatusCode::BadNodeIdUnknown
            });
        }
        Ok(())
    }

    async fn call(
        &self,
        context: &RequestContext,
        _space: &RwLock<AddressSpace>,
        methods_to_call: &mut [&mut &mut MethodCall],
    ) -> Result<(), StatusCode> {
        let by = Caller::of(context, &self.peers).actor();
        for call in methods_to_call.iter_mut() {
            self.call_one(context, &by, call).await;
        }
        Ok(())
    }

    async fn create_value_monitored_items(
        &self,
        context: &RequestContext,
        space: &RwLock<AddressSpace>,
        items: &mut [&mut &mut CreateMonitoredItem],
    ) {
        let to_read: Vec<&ParsedReadValueId> = items.iter().map(|i| i.item_to_monitor()).collect();
        let values = self
            .read_values(context, space, &to_read, 0.0, TimestampsToReturn::Both)
            .await;
        for (value, item) in values.into_iter().zip(items.iter_mut()) {
            // async-opcua's default would make an item Good on a node that is not there (one a
            // reload removed): refused, as Part 4 (5.12.2) says.
            if value.status() == StatusCode::BadNodeIdUnknown {
                item.set_status(StatusCode::BadNodeIdUnknown);
                continue;
            }
            if value.status() != StatusCode::BadAttributeIdInvalid {
                item.set_initial_value(value);
            }
            item.set_status(StatusCode::Good);
        }
    }
}

/// The aggregate of each of the `count` nodes of a processed read handed to this manager.
/// async-opcua hands a node manager only the nodes it owns that passed its own checks,
/// without their places in the request, so the `i`-th aggregate belongs to the `i`-th
/// node only when every node came (as many as aggregates). Otherwise the aggregates are
/// known only when they are all the same; when they differ, the nodes are refused
/// (`Bad_AggregateInvalidInputs`) rather than given another node's aggregate.
pub(crate) fn aggregates_of(
    aggregates: &[NodeId],
    count: usize,
) -> Result<Vec<Option<&NodeId>>, StatusCode> {
    if aggregates.len() < count {
        return Err(StatusCode::BadAggregateListMismatch);
    }
    if aggregates.len() == count {
        return Ok(aggregates.iter().map(Some).collect());
    }
    match aggregates.split_first() {
        Some((first, rest)) if rest.iter().all(|a| a == first) => Ok(vec![Some(first); count]),
        _ => Err(StatusCode::BadAggregateInvalidInputs),
    }
}

/// What one call of a raw read of `point`'s history needs from the history.
pub(crate) async fn fetch_raw(
    cell: &Arc<Cell>,
    point: PointId,
    read: &RawRead,
) -> Result<Fetched, StatusCode> {
    let cell = Arc::clone(cell);
    let read = read.clone();
    tokio::task::spawn_blocking(move || {
        let store = cell.store();
        let range = read.range;
        let start_bound = if read.wants_start_bound() {
            Some(store.history_nearest(&point, range.start(), range.reverse)?)
        } else {
            None
        };
        let rows = store.history_page(
            &point,
            range.from,
            range.to,
            range.order(),
            read.after,
            read.rows_wanted(),
        )?;
        let end_bound = if read.bounds {
            Some(store.history_nearest(&point, range.end(), !range.reverse)?)
        } else {
            None
        };
        Ok(Fetched {
            start_bound,
            rows,
            end_bound,
        })
    })
    .await
    .map_err(|_| StatusCode::BadInternalError)?
    .map_err(|e: gateway::store::StoreError| {
        tracing::warn!("OPC UA history read failed: {e}");
        StatusCode::BadHistoryOperationUnsupported
    })
}

/// `point`'s stored history in `range` (every `step` when given).
pub(crate) async fn read_history(
    cell: &Arc<Cell>,
    point: PointId,
    range: history::TimeRange,
    step: Option<Duration>,
) -> Result<gateway::store::History, StatusCode> {
    let cell = Arc::clone(cell);
    tokio::task::spawn_blocking(move || cell.store().history(&point, range.from, range.to, step))
        .await
        .map_err(|_| StatusCode::BadInternalError)?
        .map_err(|e| {
            tracing::warn!("OPC UA history read failed: {e}");
            StatusCode::BadHistoryOperationUnsupported
        })
}

impl CellNodes {
    /// One call of a method of `Objects/Gateway/Alarms`: refused unless writes are on and
    /// the user may write (as a write), else the action through the alarm keeper, in a
    /// task of its own (journalled and committed even if the client leaves).
    async fn call_one(&self, context: &RequestContext, by: &str, call: &mut MethodCall) {
        let Some(method) = Method::of(self.ns, call.method_id()) else {
            call.set_status(StatusCode::BadMethodInvalid);
            return;
        };
        if !self.users.may_write(&context.token) {
            tracing::info!(
                "OPC UA {} refused: {}",
                method.name(),
                if context.token.is_anonymous() {
                    "anonymous sessions do not act on alarms".to_owned()
                } else {
                    format!("user {} may not write (or writes are off)", context.token.0)
                }
            );
            call.set_status(StatusCode::BadUserAccessDenied);
            return;
        }
        let asked = match alarms::asked(method, call.arguments()) {
            Ok(asked) => asked,
            Err(BadArguments::Status(status)) => {
                call.set_status(status);
                return;
            }
            Err(BadArguments::Each(results)) => {
                call.set_argument_error(results);
                return;
            }
        };
        let cell = Arc::clone(&self.cell);
        let by = by.to_owned();
        let alarm = asked.alarm.clone();
        let done = tokio::spawn(async move {
            gateway::alarm::keeper::act(
                &cell,
                &asked.alarm,
                asked.action,
                &by,
                asked.comment.as_deref(),
            )
            .await
        });
        match done.await {
            Ok(Ok(view)) => {
                call.set_outputs(vec![Variant::from(view.state.as_str())]);
                call.set_status(StatusCode::Good);
            }
            Ok(Err(error)) => {
                tracing::info!("OPC UA {} of {alarm} refused: {error}", method.name());
                let status = alarms::act_status(&error);
                if matches!(error, gateway::alarm::book::ActError::Unknown { .. }) {
                    let mut results = vec![StatusCode::Good; call.arguments().len()];
                    results[0] = status;
                    call.set_argument_error(results);
                } else {
                    call.set_status(status);
                }
            }
            Err(_) => call.set_status(StatusCode::BadInternalError),
        }
    }
}

/// One write of `point` (of `kind`): refused before anything is stored unless writes are
/// on and the user may write; from there through the audited write path.
pub(crate) async fn write_one(
    cell: &Arc<Cell>,
    users: &Users,
    context: &RequestContext,
    client: &str,
    (point, kind): (PointId, PointKind),
    write: &::opcua::server::node_manager::ParsedWriteValue,
) -> StatusCode {
    if write.attribute_id != AttributeId::Value {
        return StatusCode::BadNotWritable;
    }
    if !users.may_write(&context.token) {
        tracing::info!(
            "OPC UA write to {point} refused: {}",
            if context.token.is_anonymous() {
                "anonymous sessions do not write".to_owned()
            } else {
                format!("user {} may not write (or writes are off)", context.token.0)
            }
        );
        return StatusCode::BadUserAccessDenied;
    }
    if write.index_range != NumericRange::None {
        return StatusCode::BadIndexRangeInvalid;
    }
    let given = write.value.value.clone().unwrap_or(Variant::Empty);
    let refuse = |words: String| {
        let attempt = Attempt::new(
            Arc::clone(cell),
            client,
            point.device(),
            point.to_string(),
            space::variant_json(&given),
        );
        async move { attempt.refuse(&words, None).await }
    };
    // The gateway writes values only: a status other than Good, or a time, that the
    // client sets would be dropped on the way (a Bad value must never reach a device as
    // a good one). OPC UA Part 4, 5.10.4: Bad_WriteNotSupported.
    let value = &write.value;
    if value.status.is_some_and(|s| !s.is_good())
        || value.source_timestamp.is_some()
        || value.server_timestamp.is_some()
    {
        refuse(format!(
            "{point}: a write carries a value only, not a status (other than Good) or timestamps"
        ))
        .await;
        return StatusCode::BadWriteNotSupported;
    }
    let Some((value, json)) = space::written_value(&kind, &given) else {
        refuse(format!(
            "{point} takes {:?}, not {}",
            space::data_type(&kind),
            space::variant_kind(&given)
        ))
        .await;
        return StatusCode::BadTypeMismatch;
    };
    let attempt = Attempt::new(Arc::clone(cell), client, point.device(), point.name(), json);
    // A task of its own: the write and its audit rows finish even if the client leaves.
    let done = tokio::spawn(attempt.carry_out(point, value));
    match done.await {
        Ok(Ok(_)) => StatusCode::Good,
        Ok(Err(error)) => write_status(&error),
        Err(_) => StatusCode::BadInternalError,
    }
}

/// The status code of a refused or failed write.
pub fn write_status(error: &WriteError) -> StatusCode {
    match error {
        WriteError::Invalid(ValueError::ReadOnly { .. }) => StatusCode::BadNotWritable,
        WriteError::Invalid(ValueError::WrongType { .. }) => StatusCode::BadTypeMismatch,
        WriteError::Invalid(_) => StatusCode::BadOutOfRange,
        WriteError::UnknownPoint { .. } => StatusCode::BadNodeIdUnknown,
        WriteError::Device(e) if e.kind == ErrorKind::Refused => StatusCode::BadOutOfRange,
        WriteError::Device(e) if e.kind == ErrorKind::Usage => StatusCode::BadOutOfRange,
        // The device did not answer or its line is not running (`Device`, `NotRunning`), or
        // a failure `WriteError` gains later (it is `non_exhaustive`): nothing was written.
        _ => StatusCode::BadCommunicationError,
    }
}

/// Who a request comes from: the user (or `anonymous`), the client's address when the
/// relay knows it, the session and the client's application URI.
pub(crate) struct Caller {
    user: String,
    from: Option<std::net::SocketAddr>,
    session: String,
    uri: String,
}

impl Caller {
    pub(crate) fn of(context: &RequestContext, peers: &Peers) -> Self {
        let session = context.session.read();
        Self {
            user: if context.token.is_anonymous() {
                "anonymous".to_owned()
            } else {
                format!("user {}", context.token.0)
            },
            from: peers.address(session.secure_channel_id()),
            session: context.session_id.to_string(),
            uri: session
                .application_description()
                .application_uri
                .as_ref()
                .to_owned(),
        }
    }

    /// For the alarm journal, the address first (the journal keeps 128 characters):
    /// `opcua user op from 192.0.2.7:50112 (session 3, urn:client:app)`.
    fn actor(&self) -> String {
        let from = self.from.map(|a| format!(" from {a}")).unwrap_or_default();
        format!(
            "opcua {}{from} (session {}, {})",
            self.user, self.session, self.uri
        )
    }

    /// For the audit log: `opcua user op (session 3, urn:client:app, from 192.0.2.7:50112)`.
    pub(crate) fn client(&self) -> String {
        let from = self.from.map(|a| format!(", from {a}")).unwrap_or_default();
        format!(
            "opcua {} (session {}, {}{from})",
            self.user, self.session, self.uri
        )
    }
}
