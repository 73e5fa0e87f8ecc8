//! What one birth (NBIRTH or DBIRTH) said about its metrics, for resolving the aliases
//! and names of the data that follow it. Shared by the [`crate::Describer`] (which only
//! needs names and datatypes) and the [`crate::Host`] (which keeps, beside each metric,
//! the point it records it as).
//!
//! A host keeps one table per birth for as long as the node lives, so each metric's name
//! is held once (the entry and the name index share it, and the host's point key too).

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use crate::proto::Metric;

/// One metric of a birth: its name and what the reader keeps beside it (the datatype, as
/// the reader needs it).
#[derive(Debug, Clone)]
pub(crate) struct Known<T> {
    /// The name.
    pub(crate) name: Arc<str>,
    /// The reader's own data about the metric.
    pub(crate) extra: T,
}

/// The metrics of one birth, found by alias or by name.
#[derive(Debug, Clone)]
pub(crate) struct Table<T> {
    metrics: Vec<Known<T>>,
    by_alias: HashMap<u64, usize>,
    by_name: HashMap<Arc<str>, usize>,
    /// Aliases the birth gave to more than one metric: data by them cannot be resolved.
    ambiguous: Vec<u64>,
    /// Aliases of metrics the birth gave but the reader left out (no name, a name it
    /// refuses): their data is known to be dropped.
    left_out: HashSet<u64>,
}

impl<T> Default for Table<T> {
    fn default() -> Self {
        Self {
            metrics: Vec::new(),
            by_alias: HashMap::new(),
            by_name: HashMap::new(),
            ambiguous: Vec::new(),
            left_out: HashSet::new(),
        }
    }
}

impl<T> Table<T> {
    /// The table of a birth's `metrics`: every metric with a name for which `extra` gives
    /// the reader's data (by its place in the payload and its name); `None` leaves it out,
    /// as a metric without a name is (the caller may report them). When a name comes
    /// twice, the later metric wins. An alias given to two metrics names neither: data by
    /// it falls back to its name, if it has one ([`Table::ambiguous_aliases`]).
    pub(crate) fn of_birth(
        metrics: &[Metric],
        mut extra: impl FnMut(usize, &Arc<str>, &Metric) -> Option<T>,
    ) -> Self {
        let mut table = Self::default();
        let mut ambiguous = HashSet::new();
        for (index, m) in metrics.iter().enumerate() {
            let kept = m.name.as_deref().and_then(|name| {
                let name: Arc<str> = Arc::from(name);
                let extra = extra(index, &name, m)?;
                Some((name, extra))
            });
            let Some((name, extra)) = kept else {
                table.left_out.extend(m.alias);
                continue;
            };
            let at = table.metrics.len();
            table.by_name.insert(Arc::clone(&name), at);
            table.metrics.push(Known { name, extra });
            if let Some(alias) = m.alias
                && !ambiguous.contains(&alias)
                && table.by_alias.insert(alias, at).is_some()
            {
                table.by_alias.remove(&alias);
                ambiguous.insert(alias);
                table.ambiguous.push(alias);
            }
        }
        table.metrics.shrink_to_fit();
        table
    }

    /// The aliases the birth gave to more than one metric, in the order first seen twice.
    pub(crate) fn ambiguous_aliases(&self) -> &[u64] {
        &self.ambiguous
    }

    /// The metric a data or command metric stands for: by its alias when the birth
    /// gave that alias, else by its name.
    pub(crate) fn lookup(&self, m: &Metric) -> Option<&Known<T>> {
        let by_alias = m.alias.and_then(|alias| self.by_alias.get(&alias));
        let at = by_alias.or_else(|| self.by_name.get(m.name.as_deref()?))?;
        self.metrics.get(*at)
    }

    /// Whether a data metric that [`Table::lookup`] does not find stands for a metric the
    /// birth gave and the reader left out (by its alias).
    pub(crate) fn left_out(&self, m: &Metric) -> bool {
        m.alias.is_some_and(|alias| self.left_out.contains(&alias))
    }

    /// Every metric, in birth order.
    pub(crate) fn iter(&self) -> impl Iterator<Item = &Known<T>> {
        self.metrics.iter()
    }
}
