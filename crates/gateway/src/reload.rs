//! Reloading the configuration while the gateway runs (`SIGHUP`, `systemctl reload
//! cellbus`).
//!
//! [`plan`] compares the configuration in force with the new one, line by line, without
//! any I/O: a line whose table (endpoint, settings, devices) is the same keeps its task,
//! untouched, so its devices keep polling without a gap; a line added gets a task, a line
//! removed loses its task, and a line changed in any way has its task stopped and a new one
//! started. A device on a restarted line whose own table did not change keeps its state
//! (status, values), so interfaces see no change for it.
//!
//! [`Reloader::reload`] carries a plan out: the file is checked exactly as at the start
//! (`cellbus config check`); the new lines' drivers are built before anything stops; then
//! the changed and removed lines' tasks finish their request and stop, the cell's roster,
//! alarms and production plan are replaced in one step (each alarm that stays keeps its
//! state), a `config_reloaded` event lists the devices added, removed and changed (the
//! interfaces read it from the change stream: Sparkplug DBIRTH/DDEATH, OPC UA nodes, the
//! page), and the new tasks start. A file that fails its check changes nothing: a
//! `config_refused` event and `/healthz`'s `config.error` say why.
//!
//! What a reload does not apply: the tokens and the interfaces' tables (`[mqtt]`,
//! `[opcua]`), whose sessions a reload keeps; a reload that finds them changed says they
//! need a restart.

use std::sync::Arc;

use crate::cell::{Cell, LinePlan, Roster};
use crate::config::{CellConfig, LineConfig, Plugins, check_config};
use crate::event::{Event, EventKind, Fields};
use crate::point::DeviceId;
use crate::pollers::Pollers;
use crate::scheduler::{LineTask, Opener};
use crate::time::Timestamp;

/// What a reload changes, from two configurations.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Plan {
    /// Lines whose task stops: removed or changed.
    pub stop: Vec<String>,
    /// Lines whose task starts: added or changed.
    pub start: Vec<String>,
    /// Lines that keep their task.
    pub kept: Vec<String>,
    /// Devices the new file adds.
    pub added: Vec<DeviceId>,
    /// Devices it no longer has.
    pub removed: Vec<DeviceId>,
    /// Devices in both whose table changed.
    pub changed: Vec<DeviceId>,
    /// What differs but only a restart applies (`[mqtt]`, `token`).
    pub restart_needed: Vec<String>,
}

impl Plan {
    /// Whether the reload changes nothing that runs.
    pub fn is_empty(&self) -> bool {
        self.stop.is_empty() && self.start.is_empty()
    }
}

/// What reloading `old` as `new` changes.
pub fn plan(old: &CellConfig, new: &CellConfig) -> Plan {
    let mut plan = Plan::default();
    let old_line = |name: &str| old.lines.iter().find(|l| l.name == name);
    for line in &new.lines {
        match old_line(&line.name) {
            Some(before) if before == line => plan.kept.push(line.name.clone()),
            Some(_) => {
                plan.stop.push(line.name.clone());
                plan.start.push(line.name.clone());
            }
            None => plan.start.push(line.name.clone()),
        }
    }
    for line in &old.lines {
        if !new.lines.iter().any(|l| l.name == line.name) {
            plan.stop.push(line.name.clone());
        }
    }
    let devices = |config: &CellConfig| -> Vec<(DeviceId, crate::config::DeviceConfig)> {
        config
            .lines
            .iter()
            .flat_map(|l| &l.devices)
            .map(|d| (d.driver.id.clone(), d.clone()))
            .collect()
    };
    let (before, after) = (devices(old), devices(new));
    for (id, device) in &after {
        match before.iter().find(|(b, _)| b == id) {
            None => plan.added.push(id.clone()),
            Some((_, was)) if was != device => plan.changed.push(id.clone()),
            Some(_) => {}
        }
    }
    for (id, _) in &before {
        if !after.iter().any(|(a, _)| a == id) {
            plan.removed.push(id.clone());
        }
    }
    if old.token != new.token {
        plan.restart_needed.push("token".to_owned());
    }
    if old.read_token != new.read_token {
        plan.restart_needed.push("read_token".to_owned());
    }
    let tables = old.interfaces.keys().chain(new.interfaces.keys());
    let mut tables: Vec<&str> = tables.copied().collect();
    tables.sort_unstable();
    tables.dedup();
    for table in tables {
        if old.interfaces.get(table) != new.interfaces.get(table) {
            plan.restart_needed.push(format!("[{table}]"));
        }
    }
    plan
}

/// Makes the opener of a configured line (production: [`crate::scheduler::line_opener`]).
pub type Openers = Arc<dyn Fn(&LineConfig) -> Opener + Send + Sync>;

/// Reloads the configuration of a running gateway.
pub struct Reloader {
    cell: Arc<Cell>,
    pollers: Arc<Pollers>,
    plugins: Plugins,
    openers: Openers,
    /// The configuration in force; held through a reload, so reloads come one at a time.
    config: tokio::sync::Mutex<CellConfig>,
}

impl std::fmt::Debug for Reloader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reloader")
            .field("pollers", &self.pollers)
            .finish_non_exhaustive()
    }
}

/// Why a reload changed nothing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// The gateway runs the demo cell, which has no file.
    #[error(
        "the demo cell has no configuration file to reload; start with --config FILE to reload one"
    )]
    NoFile,
    /// The file fails its check, or a line's driver cannot be built.
    #[error("configuration not reloaded: {0}; the configuration in force stays")]
    Invalid(String),
}

impl Reloader {
    /// A reloader for the gateway whose cell is `cell`, lines polled by `pollers`, started
    /// with `config`; the kinds and tables a file may name are `plugins`'.
    pub fn new(
        cell: Arc<Cell>,
        pollers: Arc<Pollers>,
        plugins: Plugins,
        openers: Openers,
        config: CellConfig,
    ) -> Self {
        Self {
            cell,
            pollers,
            plugins,
            openers,
            config: tokio::sync::Mutex::new(config),
        }
    }

    /// Reads the configuration file again and applies it (see the module's words); returns
    /// what it changed.
    pub async fn reload(&self) -> Result<Plan, Refused> {
        let mut current = self.config.lock().await;
        let Some(path) = current.source.clone() else {
            tracing::warn!("{}", Refused::NoFile);
            return Err(Refused::NoFile);
        };
        let plugins = self.plugins.clone();
        let checked = {
            let path = path.clone();
            tokio::task::spawn_blocking(move || check_config(&path, &plugins)).await
        };
        let new = match checked {
            Ok(Ok(new)) => new,
            Ok(Err(e)) => return Err(self.refuse(&path, e.to_string())),
            Err(e) => return Err(self.refuse(&path, format!("the check failed: {e}"))),
        };
        for warning in new.warnings() {
            tracing::warn!("{}: {warning}", path.display());
        }
        let plan = plan(&current, &new);
        // Everything that can fail comes before anything stops.
        let now = Timestamp::now();
        let mut started: Vec<(usize, LinePlan)> = Vec::new();
        for (index, line) in new.lines.iter().enumerate() {
            if !plan.start.contains(&line.name) {
                continue;
            }
            match LinePlan::new(line, now) {
                Ok(plan) => started.push((index, plan)),
                Err(e) => return Err(self.refuse(&path, format!("line {}: {e}", line.name))),
            }
        }
        let old = self.cell.roster();
        let roster = match new_roster(&new, &old, &started) {
            Ok(roster) => roster,
            Err(e) => return Err(self.refuse(&path, e)),
        };
        self.pollers.stop_lines(&plan.stop).await;
        for line in old.lines().iter().filter(|l| plan.stop.contains(&l.name)) {
            crate::scheduler::forget_metrics(self.cell.metrics(), &line.name, &line.devices);
        }
        // The devices of a restarted line that did not change carry on where they were.
        for (_, line) in &started {
            for device in &line.roster_part().1 {
                if let Some(before) = old.device(device.id.as_str())
                    && !plan.changed.contains(&device.id)
                {
                    device.take_state_of(before);
                }
            }
        }
        self.cell.replace_roster(roster, &new);
        self.cell.note_config(None);
        self.cell.emit(reloaded_event(&plan, &path));
        for (index, line) in started {
            let config = &new.lines[index];
            let task = LineTask::new(Arc::clone(&self.cell), line, (self.openers)(config));
            // A line asked for more polls than it can carry, as at the start.
            if let Some(serial) = crate::load::serial_line(config)
                && let Some(warning) = task.load(serial).warning()
            {
                tracing::warn!("{}: {warning}", path.display());
            }
            self.pollers.add(task);
        }
        *current = new;
        Ok(plan)
    }

    /// Notes and tells that the file at `path` was refused for `error`.
    fn refuse(&self, path: &std::path::Path, error: String) -> Refused {
        self.cell.note_config(Some(error.clone()));
        let mut fields = Fields::new();
        fields.insert("path".into(), serde_json::json!(path.display().to_string()));
        fields.insert("error".into(), serde_json::json!(error));
        let refused = Refused::Invalid(error);
        self.cell.emit(Event {
            fields,
            ..Event::of_gateway(
                EventKind::ConfigRefused,
                format!("{} ({})", refused, path.display()),
            )
        });
        refused
    }
}

/// The roster of `new`: each kept line as it is in `old`, each started line from its plan.
fn new_roster(
    new: &CellConfig,
    old: &Roster,
    started: &[(usize, LinePlan)],
) -> Result<Roster, String> {
    let mut parts = Vec::new();
    for (index, line) in new.lines.iter().enumerate() {
        if let Some((_, plan)) = started.iter().find(|(i, _)| *i == index) {
            parts.push(plan.roster_part());
            continue;
        }
        let entry = old
            .lines()
            .iter()
            .find(|l| l.name == line.name)
            .ok_or_else(|| format!("line {} is neither kept nor started", line.name))?;
        let devices = entry
            .devices
            .iter()
            .filter_map(|id| old.device(id.as_str()).cloned())
            .collect();
        parts.push((Arc::clone(entry), devices));
    }
    Roster::of(parts)
}

/// The `config_reloaded` event of `plan`, applied from `path`.
fn reloaded_event(plan: &Plan, path: &std::path::Path) -> Event {
    let ids = |ids: &[DeviceId]| ids.iter().map(|d| d.to_string()).collect::<Vec<_>>();
    let mut said = Vec::new();
    for (what, devices) in [
        ("added", &plan.added),
        ("removed", &plan.removed),
        ("changed", &plan.changed),
    ] {
        if !devices.is_empty() {
            said.push(format!("devices {what}: {}", ids(devices).join(", ")));
        }
    }
    if said.is_empty() && plan.is_empty() {
        said.push("no line or device changed".to_owned());
    }
    let mut message = format!(
        "configuration reloaded from {}: {}; {} lines keep polling",
        path.display(),
        said.join("; "),
        plan.kept.len()
    );
    if !plan.restart_needed.is_empty() {
        message.push_str(&format!(
            "; changed but applied only by a restart: {}",
            plan.restart_needed.join(", ")
        ));
    }
    let mut fields = Fields::new();
    fields.insert("path".into(), serde_json::json!(path.display().to_string()));
    fields.insert("added".into(), serde_json::json!(ids(&plan.added)));
    fields.insert("removed".into(), serde_json::json!(ids(&plan.removed)));
    fields.insert("changed".into(), serde_json::json!(ids(&plan.changed)));
    fields.insert("lines_stopped".into(), serde_json::json!(plan.stop));
    fields.insert("lines_started".into(), serde_json::json!(plan.start));
    fields.insert("lines_kept".into(), serde_json::json!(plan.kept));
    fields.insert(
        "restart_needed".into(),
        serde_json::json!(plan.restart_needed),
    );
    Event {
        fields,
        ..Event::of_gateway(EventKind::ConfigReloaded, message)
    }
}

/// The devices a `config_reloaded` event lists under `field` (`added`, `removed`,
/// `changed`): what an interface reads to follow a reload.
pub fn devices_in(event: &Event, field: &str) -> Vec<DeviceId> {
    event
        .fields
        .get(field)
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
        .filter_map(|v| v.as_str())
        .filter_map(|id| DeviceId::new(id).ok())
        .collect()
}

/// Reloads on every `SIGHUP` until `stop` turns true, telling systemd (`RELOADING=1`, then
/// `READY=1`).
#[cfg(unix)]
pub async fn on_hangup(
    reloader: Arc<Reloader>,
    mut hangups: tokio::signal::unix::Signal,
    mut stop: tokio::sync::watch::Receiver<bool>,
) {
    loop {
        tokio::select! {
            _ = stop.wait_for(|stop| *stop) => return,
            got = hangups.recv() => if got.is_none() { return },
        }
        crate::service::reloading();
        let status = match reloader.reload().await {
            Ok(_) => "configuration reloaded".to_owned(),
            Err(refused) => refused.to_string(),
        };
        crate::service::ready(&status);
    }
}

#[cfg(test)]
mod tests;
