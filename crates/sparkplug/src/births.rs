//! What one birth (NBIRTH or DBIRTH) said about its metrics, for resolving the aliases
//! and names of the data that follow it. Shared by the [`crate::Describer`] (which only
//! needs names and datatypes) and the [`crate::Host`] (which keeps, beside each metric,
//! the point it records it as).

use std::collections::{HashMap, HashSet};

use crate::proto::Metric;

/// One metric of a birth: its name, its datatype code as the birth gave it, and what the
/// reader keeps beside it.
#[derive(Debug, Clone)]
pub(crate) struct Known<T> {
    /// The name.
    pub(crate) name: String,
    /// The datatype code, if the birth gave one.
    pub(crate) datatype: Option<u32>,
    /// The reader's own data about the metric.
    pub(crate) extra: T,
}

/// The metrics of one birth, found by alias or by name.
#[derive(Debug, Clone)]
pub(crate) struct Table<T> {
    metrics: Vec<Known<T>>,
    by_alias: HashMap<u64, usize>,
    by_name: HashMap<String, usize>,
    /// Aliases the birth gave to more than one metric: data by them cannot be resolved.
    ambiguous: Vec<u64>,
}

impl<T> Default for Table<T> {
    fn default() -> Self {
        Self {
            metrics: Vec::new(),
            by_alias: HashMap::new(),
            by_name: HashMap::new(),
            ambiguous: Vec::new(),
        }
    }
}

impl<T> Table<T> {
    /// The table of a birth's `metrics`: every metric with a name, `extra` giving the
    /// reader's data for each (by its place in the payload). Metrics without a name are
    /// left out (the caller may report them); when a name comes twice, the later metric
    /// wins. An alias given to two metrics names neither: data by it falls back to its
    /// name, if it has one ([`Table::ambiguous_aliases`]).
    pub(crate) fn of_birth(metrics: &[Metric], mut extra: impl FnMut(usize, &Metric) -> T) -> Self {
        let mut table = Self::default();
        let mut ambiguous = HashSet::new();
        for (index, m) in metrics.iter().enumerate() {
            let Some(name) = &m.name else { continue };
            let at = table.metrics.len();
            table.metrics.push(Known {
                name: name.clone(),
                datatype: m.datatype,
                extra: extra(index, m),
            });
            table.by_name.insert(name.clone(), at);
            if let Some(alias) = m.alias
                && !ambiguous.contains(&alias)
                && table.by_alias.insert(alias, at).is_some()
            {
                table.by_alias.remove(&alias);
                ambiguous.insert(alias);
                table.ambiguous.push(alias);
            }
        }
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

    /// Every metric, in birth order.
    pub(crate) fn iter(&self) -> impl Iterator<Item = &Known<T>> {
        self.metrics.iter()
    }
}
