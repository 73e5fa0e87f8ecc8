//! Sparkplug topics: `spBv1.0/{group}/{message_type}/{edge_node}[/{device}]` and the
//! host's `spBv1.0/STATE/{host}`, typed so that a node message cannot name a device
//! and a device message cannot lack one.

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;

/// The first level of every Sparkplug B topic.
pub const NAMESPACE: &str = "spBv1.0";
/// The second level of a host application's STATE topic.
pub const STATE: &str = "STATE";

/// The characters an id must not contain: MQTT's level separator and wildcards.
const FORBIDDEN: [char; 3] = ['/', '+', '#'];

/// The longest id or metric name taken, in bytes. A real one is a few dozen; a rogue
/// client's 100 kB names would otherwise be kept and stored as sent.
pub const MAX_NAME_BYTES: usize = 256;

/// How many characters of a refused name an error quotes.
const QUOTED_CHARS: usize = 32;

/// The first character of `text` that would hide or reorder what a user reads: a control
/// character (C0, DEL, C1) or a Unicode bidirectional formatting character (the marks
/// U+200E, U+200F and U+061C, the embeddings and overrides U+202A–U+202E, the isolates
/// U+2066–U+2069). Names and ids with one are refused: a right-to-left override shows
/// `temp_lio` as `oil_pmet` in every table and dashboard.
pub(crate) fn misleading_character(text: &str) -> Option<char> {
    text.chars().find(|&c| {
        c.is_control()
            || matches!(
                c,
                '\u{200e}' | '\u{200f}' | '\u{061c}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}'
            )
    })
}

/// The start of a too long `text`, for an error message: its first few characters.
pub(crate) fn quoted_start(text: &str) -> String {
    text.chars().take(QUOTED_CHARS).collect()
}

/// A group, edge node, device or host id: non-empty UTF-8 of at most [`MAX_NAME_BYTES`]
/// bytes, without `/`, `+`, `#` ([`FORBIDDEN`]), control or bidirectional formatting
/// characters ([`misleading_character`]). Shared text: a clone (every point of a birth
/// names its node) copies no bytes.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Id(Arc<str>);

/// Why a string is not an [`Id`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IdError {
    /// The id is the empty string.
    #[error("an id must not be empty")]
    Empty,
    /// The id contains a character MQTT reserves.
    #[error("the id {id:?} contains {character:?}, which MQTT topics reserve")]
    Forbidden {
        /// The id as given.
        id: String,
        /// The first reserved character in it.
        character: char,
    },
    /// The id is longer than [`MAX_NAME_BYTES`].
    #[error("the id {start:?}… is {bytes} bytes long; at most {MAX_NAME_BYTES} are taken")]
    TooLong {
        /// Its first characters.
        start: String,
        /// Its length in bytes.
        bytes: usize,
    },
    /// The id contains a control or bidirectional formatting character.
    #[error(
        "the id {id:?} contains {character:?}, a control or bidirectional formatting \
         character, which would hide or reorder what is shown"
    )]
    Misleading {
        /// The id as given.
        id: String,
        /// The first such character in it.
        character: char,
    },
}

impl Id {
    /// Checks `id` and keeps it.
    pub fn new(id: impl AsRef<str>) -> Result<Self, IdError> {
        let id = id.as_ref();
        if id.is_empty() {
            return Err(IdError::Empty);
        }
        if id.len() > MAX_NAME_BYTES {
            return Err(IdError::TooLong {
                start: quoted_start(id),
                bytes: id.len(),
            });
        }
        if let Some(character) = id.chars().find(|c| FORBIDDEN.contains(c)) {
            let id = id.to_owned();
            return Err(IdError::Forbidden { id, character });
        }
        if let Some(character) = misleading_character(id) {
            let id = id.to_owned();
            return Err(IdError::Misleading { id, character });
        }
        Ok(Self(Arc::from(id)))
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for Id {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl FromStr for Id {
    type Err = IdError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

/// What a message is about; the topic's `N`/`D` prefix says whether it is the edge
/// node's own or one of its devices'.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    /// `NBIRTH` / `DBIRTH`: every metric with its type and value.
    Birth,
    /// `NDATA` / `DDATA`: changed metrics.
    Data,
    /// `NDEATH` / `DDEATH`: gone offline.
    Death,
    /// `NCMD` / `DCMD`: a host's command.
    Command,
}

impl MessageKind {
    fn suffix(self) -> &'static str {
        match self {
            Self::Birth => "BIRTH",
            Self::Data => "DATA",
            Self::Death => "DEATH",
            Self::Command => "CMD",
        }
    }

    fn from_suffix(s: &str) -> Option<Self> {
        match s {
            "BIRTH" => Some(Self::Birth),
            "DATA" => Some(Self::Data),
            "DEATH" => Some(Self::Death),
            "CMD" => Some(Self::Command),
            _ => None,
        }
    }
}

/// A Sparkplug B topic.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `spBv1.0/{group}/N{kind}/{edge_node}`.
    Node {
        /// The group id.
        group: Id,
        /// BIRTH, DATA, DEATH or CMD.
        kind: MessageKind,
        /// The edge node id.
        edge_node: Id,
    },
    /// `spBv1.0/{group}/D{kind}/{edge_node}/{device}`.
    Device {
        /// The group id.
        group: Id,
        /// BIRTH, DATA, DEATH or CMD.
        kind: MessageKind,
        /// The edge node id.
        edge_node: Id,
        /// The device id.
        device: Id,
    },
    /// `spBv1.0/STATE/{host}`: a host application's online state.
    State {
        /// The host application's id.
        host: Id,
    },
}

impl Topic {
    /// An edge node's or device's message as (group, kind, edge node, device: `None` for
    /// the node's own); a host's STATE as `Err` with the host's id.
    pub fn into_edge(self) -> Result<(Id, MessageKind, Id, Option<Id>), Id> {
        match self {
            Topic::Node {
                group,
                kind,
                edge_node,
            } => Ok((group, kind, edge_node, None)),
            Topic::Device {
                group,
                kind,
                edge_node,
                device,
            } => Ok((group, kind, edge_node, Some(device))),
            Topic::State { host } => Err(host),
        }
    }

    /// The message type as the topic spells it (`NBIRTH`, `DCMD`, `STATE`).
    pub fn message_type(&self) -> String {
        match self {
            Self::Node { kind, .. } => format!("N{}", kind.suffix()),
            Self::Device { kind, .. } => format!("D{}", kind.suffix()),
            Self::State { .. } => STATE.to_owned(),
        }
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Node {
                group, edge_node, ..
            } => write!(f, "{NAMESPACE}/{group}/{}/{edge_node}", self.message_type()),
            Self::Device {
                group,
                edge_node,
                device,
                ..
            } => write!(
                f,
                "{NAMESPACE}/{group}/{}/{edge_node}/{device}",
                self.message_type()
            ),
            Self::State { host } => write!(f, "{NAMESPACE}/{STATE}/{host}"),
        }
    }
}

/// Why a string is not a Sparkplug B topic.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TopicError {
    /// The first level is not `spBv1.0`.
    #[error("a Sparkplug B topic starts with {NAMESPACE:?}, not {found:?}")]
    Namespace {
        /// The first level as given.
        found: String,
    },
    /// The message type is none of the eight, nor STATE.
    #[error(
        "{found:?} is not a Sparkplug message type (NBIRTH, NDATA, NDEATH, NCMD, DBIRTH, DDATA, DDEATH, DCMD)"
    )]
    MessageType {
        /// The level as given.
        found: String,
    },
    /// The topic has too few or too many levels for its message type.
    #[error("a {message_type} topic has {expected} levels, this one has {found}")]
    Levels {
        /// The message type read from the topic.
        message_type: String,
        /// How many levels it needs.
        expected: usize,
        /// How many it has.
        found: usize,
    },
    /// An id level is not a valid id.
    #[error("the {level} is not valid: {error}")]
    Id {
        /// Which id: "group id", "edge node id", "device id" or "host id".
        level: &'static str,
        /// What is wrong with it.
        error: IdError,
    },
}

impl FromStr for Topic {
    type Err = TopicError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let levels: Vec<&str> = s.split('/').collect();
        let id = |level: &'static str, text: &str| {
            Id::new(text).map_err(|error| TopicError::Id { level, error })
        };
        let namespace = levels.first().copied().unwrap_or_default();
        if namespace != NAMESPACE {
            return Err(TopicError::Namespace {
                found: namespace.to_owned(),
            });
        }
        let levels_error = |message_type: &str, expected| TopicError::Levels {
            message_type: message_type.to_owned(),
            expected,
            found: levels.len(),
        };
        if levels.get(1) == Some(&STATE) && levels.len() <= 3 {
            let [_, _, host] = levels[..] else {
                return Err(levels_error(STATE, 3));
            };
            return Ok(Self::State {
                host: id("host id", host)?,
            });
        }
        let Some(&message_type) = levels.get(2) else {
            return Err(levels_error("Sparkplug", 4));
        };
        let parsed = message_type
            .split_at_checked(1)
            .and_then(|(prefix, suffix)| Some((prefix, MessageKind::from_suffix(suffix)?)));
        match (parsed, &levels[..]) {
            (Some(("N", kind)), [_, group, _, edge_node]) => Ok(Self::Node {
                group: id("group id", group)?,
                kind,
                edge_node: id("edge node id", edge_node)?,
            }),
            (Some(("N", _)), _) => Err(levels_error(message_type, 4)),
            (Some(("D", kind)), [_, group, _, edge_node, device]) => Ok(Self::Device {
                group: id("group id", group)?,
                kind,
                edge_node: id("edge node id", edge_node)?,
                device: id("device id", device)?,
            }),
            (Some(("D", _)), _) => Err(levels_error(message_type, 5)),
            _ => Err(TopicError::MessageType {
                found: message_type.to_owned(),
            }),
        }
    }
}
