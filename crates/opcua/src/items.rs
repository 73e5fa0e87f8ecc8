//! The cap on monitored items, all sessions and all nodes together.
//!
//! async-opcua 0.19 bounds monitored items per subscription (1,000), subscriptions per
//! session (10) and sessions (100): a million items, about 1.35 GB of memory. It has no
//! global cap, but every item it keeps is created through a node manager's
//! `create_monitored_items` (an item no manager takes is not created), and each one's end
//! (deleted, its subscription deleted or expired) is reported to that manager's
//! `delete_monitored_items`. So every node manager of the server (async-opcua's own for
//! namespace 0, its diagnostics, the cell's) is wrapped in [`Capped`], which takes a place
//! in one shared [`ItemCount`] for each item before the manager sees it and refuses the
//! items beyond the cap with `Bad_TooManyMonitoredItems`; everything else is passed
//! through unchanged.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use ::opcua::nodes::DefaultTypeTree;
use ::opcua::server::CreateMonitoredItem;
use ::opcua::server::diagnostics::NamespaceMetadata;
use ::opcua::server::node_manager::{
    AddNodeItem, AddReferenceItem, BrowseNode, BrowsePathItem, DeleteNodeItem, DeleteReferenceItem,
    DynNodeManager, ExternalReferenceRequest, HistoryNode, HistoryUpdateNode, MethodCall,
    MonitoredItemRef, MonitoredItemUpdateRef, NodeManager, NodeManagerBuilder, QueryRequest,
    ReadNode, RegisterNodeItem, RequestContext, ServerContext, WriteNode,
};
use ::opcua::types::{
    ExpandedNodeId, MonitoringMode, NodeId, ReadAnnotationDataDetails, ReadAtTimeDetails,
    ReadEventDetails, ReadProcessedDetails, ReadRawModifiedDetails, StatusCode, TimestampsToReturn,
};

use crate::points::PointTable;
use gateway::write::LogThrottle;

/// The monitored items of the whole server, and how many were refused.
#[derive(Debug)]
pub struct ItemCount {
    count: AtomicU64,
    max: u64,
    refused: AtomicU64,
    /// Refusals are logged at most every 10 s (a client can ask again and again).
    logged: Mutex<LogThrottle>,
}

impl ItemCount {
    /// No items yet; at most `max` at once.
    pub fn new(max: u64) -> Self {
        Self {
            count: AtomicU64::new(0),
            max,
            refused: AtomicU64::new(0),
            logged: Mutex::default(),
        }
    }

    /// Monitored items now.
    pub fn current(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// Monitored items refused since the start.
    pub fn refused(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }

    /// Counts one more item unless there are `max` already; says whether it did.
    pub fn take(&self) -> bool {
        let taken = self
            .count
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| {
                (n < self.max).then_some(n + 1)
            })
            .is_ok();
        if !taken {
            self.refused.fetch_add(1, Ordering::Relaxed);
        }
        taken
    }

    /// Gives back the places of `n` items that are gone (or were not created).
    pub fn give_back(&self, n: u64) {
        let _ = self
            .count
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |c| {
                Some(c.saturating_sub(n))
            });
    }

    fn report(&self, refused: usize) {
        let due = self
            .logged
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .count(tokio::time::Instant::now());
        if let Some(requests) = due {
            tracing::warn!(
                "OPC UA: refused {refused} monitored item(s): the server has {} already \
                 (max_monitored_items in [opcua]); {requests} request(s) had items refused \
                 since the last report",
                self.max
            );
        }
    }
}

/// `builder`'s node manager, its monitored items counted in `items`.
pub fn capped(
    builder: impl NodeManagerBuilder + 'static,
    items: Arc<ItemCount>,
) -> impl NodeManagerBuilder {
    move |context: ServerContext| Capped {
        inner: Box::new(builder).build(context),
        items,
        yields: None,
    }
}

/// [`capped`], and the manager leaves the nodes of `points` to the points' own manager
/// (async-opcua gives each node to the first manager that says it owns it).
pub fn capped_yielding(
    builder: impl NodeManagerBuilder + 'static,
    items: Arc<ItemCount>,
    points: Arc<PointTable>,
) -> impl NodeManagerBuilder {
    move |context: ServerContext| Capped {
        inner: Box::new(builder).build(context),
        items,
        yields: Some(points),
    }
}

/// A node manager whose monitored items take places in an [`ItemCount`].
pub struct Capped {
    inner: Arc<DynNodeManager>,
    items: Arc<ItemCount>,
    /// Nodes it does not own although they are in its namespace.
    yields: Option<Arc<PointTable>>,
}

impl Capped {
    /// The node manager inside.
    pub fn inner(&self) -> &Arc<DynNodeManager> {
        &self.inner
    }
}

#[async_trait::async_trait]
impl NodeManager for Capped {
    fn owns_node(&self, id: &NodeId) -> bool {
        self.inner.owns_node(id) && !self.yields.as_ref().is_some_and(|points| points.owns(id))
    }

    fn name(&self) -> &str {
        self.inner.name()
    }

    fn owns_server_events(&self) -> bool {
        self.inner.owns_server_events()
    }

    fn handle_new_node(&self, parent_id: &ExpandedNodeId) -> bool {
        self.inner.handle_new_node(parent_id)
    }

    fn namespaces_for_user(&self, context: &RequestContext) -> Vec<NamespaceMetadata> {
        self.inner.namespaces_for_user(context)
    }

    async fn init(&self, type_tree: &mut DefaultTypeTree, context: ServerContext) {
        self.inner.init(type_tree, context).await;
    }

    async fn resolve_external_references(
        &self,
        context: &RequestContext,
        items: &mut [&mut ExternalReferenceRequest],
    ) {
        self.inner.resolve_external_references(context, items).await;
    }

    async fn read(
        &self,
        context: &RequestContext,
        max_age: f64,
        timestamps_to_return: TimestampsToReturn,
        nodes_to_read: &mut [&mut ReadNode],
    ) -> Result<(), StatusCode> {
        self.inner
            .read(context, max_age, timestamps_to_return, nodes_to_read)
            .await
    }

    async fn history_read_raw_modified(
        &self,
        context: &RequestContext,
        details: &ReadRawModifiedDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps_to_return: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        self.inner
            .history_read_raw_modified(context, details, nodes, timestamps_to_return)
            .await
    }

    async fn history_read_processed(
        &self,
        context: &RequestContext,
        details: &ReadProcessedDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps_to_return: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        self.inner
            .history_read_processed(context, details, nodes, timestamps_to_return)
            .await
    }

    async fn history_read_at_time(
        &self,
        context: &RequestContext,
        details: &ReadAtTimeDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps_to_return: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        self.inner
            .history_read_at_time(context, details, nodes, timestamps_to_return)
            .await
    }

    async fn history_read_events(
        &self,
        context: &RequestContext,
        details: &ReadEventDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps_to_return: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        self.inner
            .history_read_events(context, details, nodes, timestamps_to_return)
            .await
    }

    async fn history_read_annotations(
        &self,
        context: &RequestContext,
        details: &ReadAnnotationDataDetails,
        nodes: &mut [&mut HistoryNode],
        timestamps_to_return: TimestampsToReturn,
    ) -> Result<(), StatusCode> {
        self.inner
            .history_read_annotations(context, details, nodes, timestamps_to_return)
            .await
    }

    async fn write(
        &self,
        context: &RequestContext,
        nodes_to_write: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        self.inner.write(context, nodes_to_write).await
    }

    async fn history_update(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut HistoryUpdateNode],
    ) -> Result<(), StatusCode> {
        self.inner.history_update(context, nodes).await
    }

    async fn browse(
        &self,
        context: &RequestContext,
        nodes_to_browse: &mut [BrowseNode],
    ) -> Result<(), StatusCode> {
        self.inner.browse(context, nodes_to_browse).await
    }

    async fn translate_browse_paths_to_node_ids(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut BrowsePathItem],
    ) -> Result<(), StatusCode> {
        self.inner
            .translate_browse_paths_to_node_ids(context, nodes)
            .await
    }

    async fn register_nodes(
        &self,
        context: &RequestContext,
        nodes: &mut [&mut RegisterNodeItem],
    ) -> Result<(), StatusCode> {
        self.inner.register_nodes(context, nodes).await
    }

    async fn unregister_nodes(
        &self,
        context: &RequestContext,
        nodes: &[&NodeId],
    ) -> Result<(), StatusCode> {
        self.inner.unregister_nodes(context, nodes).await
    }

    /// Takes a place for each item before the manager sees it; the items beyond the cap
    /// get `Bad_TooManyMonitoredItems`, and the places of items the manager did not create
    /// are given back.
    async fn create_monitored_items(
        &self,
        context: &RequestContext,
        items: &mut [&mut CreateMonitoredItem],
    ) -> Result<(), StatusCode> {
        let mut admitted: Vec<&mut CreateMonitoredItem> = Vec::with_capacity(items.len());
        let mut refused = 0;
        for item in items.iter_mut() {
            if self.items.take() {
                admitted.push(&mut **item);
            } else {
                item.set_status(StatusCode::BadTooManyMonitoredItems);
                refused += 1;
            }
        }
        if refused > 0 {
            self.items.report(refused);
        }
        if admitted.is_empty() {
            return Ok(());
        }
        let result = self
            .inner
            .create_monitored_items(context, &mut admitted)
            .await;
        let not_created = match result {
            Err(_) => admitted.len(),
            Ok(()) => admitted
                .iter()
                .filter(|i| !i.status_code().is_good())
                .count(),
        };
        self.items.give_back(not_created as u64);
        result
    }

    async fn modify_monitored_items(
        &self,
        context: &RequestContext,
        items: &[&MonitoredItemUpdateRef],
    ) {
        self.inner.modify_monitored_items(context, items).await;
    }

    async fn set_monitoring_mode(
        &self,
        context: &RequestContext,
        mode: MonitoringMode,
        items: &[&MonitoredItemRef],
    ) {
        self.inner.set_monitoring_mode(context, mode, items).await;
    }

    /// Gives the items' places back (async-opcua passes only items it deleted).
    async fn delete_monitored_items(&self, context: &RequestContext, items: &[&MonitoredItemRef]) {
        self.items.give_back(items.len() as u64);
        self.inner.delete_monitored_items(context, items).await;
    }

    async fn query(
        &self,
        context: &RequestContext,
        request: &mut QueryRequest,
    ) -> Result<(), StatusCode> {
        self.inner.query(context, request).await
    }

    async fn call(
        &self,
        context: &RequestContext,
        methods_to_call: &mut [&mut MethodCall],
    ) -> Result<(), StatusCode> {
        self.inner.call(context, methods_to_call).await
    }

    async fn add_nodes(
        &self,
        context: &RequestContext,
        nodes_to_add: &mut [&mut AddNodeItem],
    ) -> Result<(), StatusCode> {
        self.inner.add_nodes(context, nodes_to_add).await
    }

    async fn add_references(
        &self,
        context: &RequestContext,
        references_to_add: &mut [&mut AddReferenceItem],
    ) -> Result<(), StatusCode> {
        self.inner.add_references(context, references_to_add).await
    }

    async fn delete_nodes(
        &self,
        context: &RequestContext,
        nodes_to_delete: &mut [&mut DeleteNodeItem],
    ) -> Result<(), StatusCode> {
        self.inner.delete_nodes(context, nodes_to_delete).await
    }

    async fn delete_node_references(
        &self,
        context: &RequestContext,
        to_delete: &[&DeleteNodeItem],
    ) {
        self.inner.delete_node_references(context, to_delete).await;
    }

    async fn delete_references(
        &self,
        context: &RequestContext,
        references_to_delete: &mut [&mut DeleteReferenceItem],
    ) -> Result<(), StatusCode> {
        self.inner
            .delete_references(context, references_to_delete)
            .await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn places_stop_at_the_cap_are_counted_when_refused_and_come_back_when_freed() {
        let items = ItemCount::new(3);
        assert!((0..3).all(|_| items.take()));
        assert!(!items.take());
        assert_eq!((items.current(), items.refused()), (3, 1));
        items.give_back(1);
        assert!(items.take());
        assert!(!items.take());
        assert_eq!((items.current(), items.refused()), (3, 2));
        items.give_back(10);
        assert_eq!(items.current(), 0);
    }
}
