//! The cell's alarms over OPC UA, sans IO: each alarm's state as variables, and the
//! methods that act on alarms, their arguments and the status codes of their refusals.
//!
//! async-opcua 0.19 has the Alarms & Conditions types in its namespace 0 but no server
//! side for them (no condition instances kept, no branches, no ConditionRefresh: it
//! answers that method with Bad_NotSupported), so the gateway's ISA-18.2 alarms are not
//! conditions. They are:
//!
//! - variables: under each device's object an `Alarms` folder, with an object per alarm
//!   (its browse name the alarm's id, `jbc1:down`) holding `State`, `Active`,
//!   `Acknowledged`, `Priority` and `ShelvedUntil`, kept current, so a client sees where
//!   every alarm is when it connects (what ConditionRefresh gives a client of conditions);
//! - events: every change is a `CellbusEventType` event (`alarm_raised`, `alarm_cleared`,
//!   `alarm_changed`, with the alarm's facts in `Fields`) on the device's object;
//! - methods: `Objects/Gateway/Alarms` has `Acknowledge(AlarmId, Comment)`,
//!   `Shelve(AlarmId, DurationSeconds, Comment)` and `Unshelve(AlarmId, Comment)`, which
//!   act as `POST /api/alarms/{id}/ack|shelve|unshelve` do, with the OPC UA user as who.

use std::time::Duration;

use ::opcua::types::{
    Argument, DataTypeId, DataValue, DateTime, LocalizedText, NodeId, StatusCode, UAString, Variant,
};

use super::space::{ids, opc_time};
use gateway::alarm::book::{ActError, Action, View};
use gateway::alarm::state::Refused;

/// The variables of an alarm's object: name, data type, words.
pub const VARIABLES: [(&str, DataTypeId, &str); 5] = [
    (
        "State",
        DataTypeId::String,
        "The alarm's ISA-18.2 state: normal, unacknowledged, acknowledged or \
         returned_unacknowledged",
    ),
    (
        "Active",
        DataTypeId::Boolean,
        "Whether its condition is active",
    ),
    (
        "Acknowledged",
        DataTypeId::Boolean,
        "Whether nobody needs to acknowledge it",
    ),
    (
        "Priority",
        DataTypeId::String,
        "Its priority: low, medium, high or urgent",
    ),
    (
        "ShelvedUntil",
        DataTypeId::DateTime,
        "Until when it is shelved (null when it is not)",
    ),
];

/// The values of alarm `view`'s variables ([`VARIABLES`]) at `t`.
pub fn values(ns: u16, view: &View, t: DateTime) -> Vec<(NodeId, DataValue)> {
    let shelved_until = view.shelved_until.map_or_else(DateTime::null, opc_time);
    let values = [
        Variant::from(view.state.as_str()),
        Variant::Boolean(view.active),
        Variant::Boolean(view.acknowledged),
        Variant::from(view.priority.as_str()),
        Variant::from(shelved_until),
    ];
    VARIABLES
        .iter()
        .zip(values)
        .map(|((name, _, _), value)| {
            (
                ids::alarm_variable(ns, &view.id, name),
                DataValue::new_at(value, t),
            )
        })
        .collect()
}

/// A method of the `Alarms` object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// `Acknowledge(AlarmId, Comment)`.
    Acknowledge,
    /// `Shelve(AlarmId, DurationSeconds, Comment)`.
    Shelve,
    /// `Unshelve(AlarmId, Comment)`.
    Unshelve,
}

impl Method {
    /// Every method.
    pub const ALL: [Method; 3] = [Method::Acknowledge, Method::Shelve, Method::Unshelve];

    /// Its browse name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Acknowledge => "Acknowledge",
            Method::Shelve => "Shelve",
            Method::Unshelve => "Unshelve",
        }
    }

    /// Its description.
    pub fn words(self) -> &'static str {
        match self {
            Method::Acknowledge => {
                "Acknowledges an alarm (active or returned to normal) with a comment, as the \
                 OPC UA user; needs what a write needs"
            }
            Method::Shelve => {
                "Shelves an alarm for DurationSeconds (1 s to 7 days) with a comment, as the \
                 OPC UA user; needs what a write needs"
            }
            Method::Unshelve => {
                "Unshelves an alarm with a comment, as the OPC UA user; needs what a write needs"
            }
        }
    }

    /// Its input arguments.
    pub fn inputs(self) -> Vec<Argument> {
        let argument = |name: &str, data_type: DataTypeId, words: &str| Argument {
            name: UAString::from(name),
            data_type: data_type.into(),
            value_rank: -1,
            array_dimensions: None,
            description: LocalizedText::new("", words),
        };
        let alarm = argument(
            "AlarmId",
            DataTypeId::String,
            "The alarm's id, as its object's browse name and /api/alarms give it \
             (jbc1:down, sealer0.temperature:high)",
        );
        let comment = argument(
            "Comment",
            DataTypeId::String,
            "Why, for the alarm journal (may be empty)",
        );
        match self {
            Method::Acknowledge | Method::Unshelve => vec![alarm, comment],
            Method::Shelve => vec![
                alarm,
                argument(
                    "DurationSeconds",
                    DataTypeId::Double,
                    "How long the alarm stays shelved, in seconds (1 s to 7 days)",
                ),
                comment,
            ],
        }
    }

    /// Its output arguments: the alarm's state after the call.
    pub fn outputs() -> Vec<Argument> {
        vec![Argument {
            name: UAString::from("State"),
            data_type: DataTypeId::String.into(),
            value_rank: -1,
            array_dimensions: None,
            description: LocalizedText::new("", "The alarm's ISA-18.2 state after the call"),
        }]
    }

    /// The method whose node is `node`, if any.
    pub fn of(ns: u16, node: &NodeId) -> Option<Method> {
        Method::ALL
            .into_iter()
            .find(|m| ids::alarm_method(ns, m.name()) == *node)
    }
}

/// What a call asks.
#[derive(Debug, Clone, PartialEq)]
pub struct Asked {
    /// The alarm's id.
    pub alarm: String,
    /// What to do.
    pub action: Action,
    /// The comment (none when empty).
    pub comment: Option<String>,
}

/// Why a call's arguments are refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BadArguments {
    /// The call's status (Bad_ArgumentsMissing, Bad_TooManyArguments,
    /// Bad_ShelvingTimeOutOfRange).
    Status(StatusCode),
    /// Each argument's result (Bad_InvalidArgument for the call).
    Each(Vec<StatusCode>),
}

/// What a call of `method` with `args` asks, or why its arguments are refused. The comment
/// may be a String or a LocalizedText (its text), empty or null.
pub fn asked(method: Method, args: &[Variant]) -> Result<Asked, BadArguments> {
    let count = method.inputs().len();
    if args.len() < count {
        return Err(BadArguments::Status(StatusCode::BadArgumentsMissing));
    }
    if args.len() > count {
        return Err(BadArguments::Status(StatusCode::BadTooManyArguments));
    }
    let mut results = vec![StatusCode::Good; count];
    let alarm = match &args[0] {
        Variant::String(s) if !s.is_empty() => s.as_ref().to_owned(),
        Variant::String(_) => {
            results[0] = StatusCode::BadInvalidArgument;
            String::new()
        }
        _ => {
            results[0] = StatusCode::BadTypeMismatch;
            String::new()
        }
    };
    let last = count - 1;
    let comment = match &args[last] {
        Variant::Empty => None,
        Variant::String(s) => Some(s.as_ref().to_owned()),
        Variant::LocalizedText(t) => Some(t.text.as_ref().to_owned()),
        _ => {
            results[last] = StatusCode::BadTypeMismatch;
            None
        }
    }
    .filter(|c| !c.is_empty());
    let mut seconds = None;
    if method == Method::Shelve {
        seconds = number(&args[1]);
        if seconds.is_none() {
            results[1] = StatusCode::BadTypeMismatch;
        }
    }
    if results.iter().any(|r| !r.is_good()) {
        return Err(BadArguments::Each(results));
    }
    let action = match method {
        Method::Acknowledge => Action::Acknowledge,
        Method::Unshelve => Action::Unshelve,
        Method::Shelve => {
            let duration = seconds
                .and_then(|s| Duration::try_from_secs_f64(s).ok())
                .ok_or(BadArguments::Status(StatusCode::BadShelvingTimeOutOfRange))?;
            Action::Shelve(duration)
        }
    };
    Ok(Asked {
        alarm,
        action,
        comment,
    })
}

/// A number of any width, as a double.
fn number(value: &Variant) -> Option<f64> {
    match value {
        Variant::Double(n) => Some(*n),
        Variant::Float(n) => Some(f64::from(*n)),
        Variant::Int64(n) => Some(*n as f64),
        Variant::UInt64(n) => Some(*n as f64),
        Variant::Int32(n) => Some(f64::from(*n)),
        Variant::UInt32(n) => Some(f64::from(*n)),
        Variant::Int16(n) => Some(f64::from(*n)),
        Variant::UInt16(n) => Some(f64::from(*n)),
        Variant::SByte(n) => Some(f64::from(*n)),
        Variant::Byte(n) => Some(f64::from(*n)),
        _ => None,
    }
}

/// The status of an action the alarms refused: the Alarms & Conditions codes where they
/// say it, Bad_InvalidArgument for an alarm that does not exist.
pub fn act_status(error: &ActError) -> StatusCode {
    match error {
        ActError::Unknown { .. } => StatusCode::BadInvalidArgument,
        ActError::Refused { refused, .. } => match refused {
            Refused::NothingToAcknowledge(_) => StatusCode::BadConditionBranchAlreadyAcked,
            Refused::NotShelved => StatusCode::BadConditionNotShelved,
            Refused::OutOfService => StatusCode::BadConditionDisabled,
            Refused::InService => StatusCode::BadConditionAlreadyEnabled,
            Refused::ShelveDuration { .. } => StatusCode::BadShelvingTimeOutOfRange,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(s: &str) -> Variant {
        Variant::from(s)
    }

    #[test]
    fn each_method_reads_its_alarm_its_comment_and_a_shelving_in_seconds() {
        assert_eq!(
            asked(Method::Acknowledge, &[text("jbc1:down"), text("seen")]),
            Ok(Asked {
                alarm: "jbc1:down".into(),
                action: Action::Acknowledge,
                comment: Some("seen".into()),
            })
        );
        let localized = Variant::from(LocalizedText::new("en", "later"));
        assert_eq!(
            asked(Method::Shelve, &[text("a"), Variant::Int32(90), localized])
                .map(|a| (a.action, a.comment)),
            Ok((
                Action::Shelve(Duration::from_secs(90)),
                Some("later".into())
            ))
        );
        assert_eq!(
            asked(Method::Unshelve, &[text("a"), Variant::Empty]).map(|a| a.comment),
            Ok(None)
        );
        assert_eq!(
            asked(Method::Unshelve, &[text("a"), text("")]).map(|a| a.comment),
            Ok(None)
        );
    }

    #[test]
    fn missing_or_mistyped_arguments_are_refused_before_any_alarm_is_touched() {
        assert_eq!(
            asked(Method::Acknowledge, &[text("a")]),
            Err(BadArguments::Status(StatusCode::BadArgumentsMissing))
        );
        assert_eq!(
            asked(Method::Unshelve, &[text("a"), text("b"), text("c")]),
            Err(BadArguments::Status(StatusCode::BadTooManyArguments))
        );
        assert_eq!(
            asked(
                Method::Shelve,
                &[Variant::Int32(1), text("soon"), text("c")]
            ),
            Err(BadArguments::Each(vec![
                StatusCode::BadTypeMismatch,
                StatusCode::BadTypeMismatch,
                StatusCode::Good
            ]))
        );
        assert_eq!(
            asked(Method::Acknowledge, &[text(""), text("c")]),
            Err(BadArguments::Each(vec![
                StatusCode::BadInvalidArgument,
                StatusCode::Good
            ]))
        );
        assert_eq!(
            asked(
                Method::Shelve,
                &[text("a"), Variant::Double(-5.0), text("c")]
            ),
            Err(BadArguments::Status(StatusCode::BadShelvingTimeOutOfRange))
        );
    }

    #[test]
    fn refusals_take_the_alarms_and_conditions_codes() {
        let refused = |refused| ActError::Refused {
            id: "a".into(),
            refused,
        };
        assert_eq!(
            act_status(&refused(Refused::NothingToAcknowledge("normal"))),
            StatusCode::BadConditionBranchAlreadyAcked
        );
        assert_eq!(
            act_status(&refused(Refused::NotShelved)),
            StatusCode::BadConditionNotShelved
        );
        assert_eq!(
            act_status(&refused(Refused::ShelveDuration {
                asked: Duration::from_secs(10_000_000),
                max: Duration::from_secs(1),
            })),
            StatusCode::BadShelvingTimeOutOfRange
        );
        assert_eq!(
            act_status(&ActError::Unknown { id: "x".into() }),
            StatusCode::BadInvalidArgument
        );
    }

    #[test]
    fn methods_are_found_by_their_node_ids_only_in_the_cells_namespace() {
        for m in Method::ALL {
            assert_eq!(Method::of(2, &ids::alarm_method(2, m.name())), Some(m));
            assert_eq!(Method::of(3, &ids::alarm_method(2, m.name())), None);
        }
        assert_eq!(Method::of(2, &ids::alarm_methods(2)), None);
    }
}
