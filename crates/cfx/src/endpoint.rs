//! What an endpoint answers to the requests of the root topic, sans IO: `AreYouThere`,
//! `WhoIsThere` (when it publishes one of the topics asked for), `GetEndpointInformation`,
//! and `NotSupportedResponse` for any other request. The response goes back to the
//! requester: its `Target` is the request's `Source`, its `RequestID` the request's.

use crate::envelope::{Envelope, Received, VERSION};
use crate::messages::{
    EndpointInformation, GetEndpointInformationResponse, Message, NotSupportedResponse,
    ThereResponse,
};
use crate::types::{Handle, RequestResult, Time};

/// The topics a placement machine's endpoint publishes.
pub const TOPICS: [&str; 4] = [
    "CFX",
    "CFX.Production",
    "CFX.ResourcePerformance",
    "CFX.ResourcePerformance.SMTPlacement",
];

/// An endpoint, as it describes itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Endpoint {
    /// Its handle.
    pub handle: Handle,
    /// Where its requests go (`amqp://gateway:5672/`), if it listens.
    pub request_uri: Option<String>,
    /// The address there.
    pub request_address: Option<String>,
    /// Its name for people.
    pub friendly_name: Option<String>,
    /// Who made the machine.
    pub vendor: Option<String>,
    /// The machine's model.
    pub model: Option<String>,
    /// Its serial number.
    pub serial: Option<String>,
    /// The software speaking for it.
    pub software: Option<String>,
}

impl Endpoint {
    /// The answer to `request`, made `at`; `None` for a request not meant for this
    /// endpoint (a `WhoIsThere` for topics it does not publish) or not a request at all.
    pub fn answer(&self, request: &Received, at: Time) -> Option<Envelope> {
        let message = match request.message_name.as_str() {
            "CFX.AreYouThereRequest" => Message::AreYouThereResponse(self.there()),
            "CFX.WhoIsThereRequest" if self.publishes_any(&request.message_body) => {
                Message::WhoIsThereResponse(self.there())
            }
            "CFX.WhoIsThereRequest" => return None,
            "CFX.GetEndpointInformationRequest" => {
                Message::GetEndpointInformationResponse(GetEndpointInformationResponse {
                    result: RequestResult::success(),
                    endpoint_information: EndpointInformation {
                        cfx_handle: self.handle.clone(),
                        cfx_version: VERSION.to_owned(),
                        request_network_uri: self.request_uri.clone(),
                        request_target_address: self.request_address.clone(),
                        unique_identifier: self.serial.clone(),
                        friendly_name: self.friendly_name.clone(),
                        vendor: self.vendor.clone(),
                        model_number: self.model.clone(),
                        serial_number: self.serial.clone(),
                        software_version: self.software.clone(),
                    },
                })
            }
            name if name.ends_with("Request") => {
                Message::NotSupportedResponse(NotSupportedResponse {
                    request_result: RequestResult::failed(&format!(
                        "{name} is not supported by {}",
                        self.handle
                    )),
                })
            }
            _ => return None,
        };
        Some(Envelope {
            target: request.source.as_deref().and_then(|s| Handle::new(s).ok()),
            request_id: request.request_id.clone(),
            ..Envelope::new(self.handle.clone(), at, message)
        })
    }

    fn there(&self) -> ThereResponse {
        ThereResponse {
            result: RequestResult::success(),
            cfx_handle: self.handle.clone(),
            request_network_uri: self.request_uri.clone(),
            request_target_address: self.request_address.clone(),
        }
    }

    /// Whether a `WhoIsThereRequest`'s body asks for a topic this endpoint publishes (or for
    /// every endpoint: no topics named).
    fn publishes_any(&self, body: &serde_json::Value) -> bool {
        let asked: Vec<&str> = body["SupportedTopics"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|t| t["TopicName"].as_str())
            .collect();
        asked.is_empty() || asked.iter().any(|topic| TOPICS.contains(topic))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn endpoint() -> Endpoint {
        Endpoint {
            handle: Handle::new("Panasonic.BM221.placer1").unwrap(),
            request_uri: Some("amqp://127.0.0.1:5673/".into()),
            request_address: Some("Panasonic.BM221.placer1".into()),
            friendly_name: Some("Placer 1".into()),
            vendor: Some("Panasonic".into()),
            model: Some("BM221".into()),
            serial: None,
            software: Some("cellbus 0.1.0".into()),
        }
    }

    fn request(name: &str, body: serde_json::Value) -> Received {
        let text = serde_json::json!({
            "MessageName": name,
            "Version": "2.1",
            "TimeStamp": "2018-03-26T16:52:25.3769532-04:00",
            "UniqueID": "f3b2c8ec-50b7-4c63-9cb3-2ed57c01880f",
            "Source": "MES.Line1.Host",
            "Target": "Panasonic.BM221.placer1",
            "RequestID": "request-42",
            "MessageBody": body,
        });
        Received::decode(text.to_string().as_bytes())
            .unwrap()
            .remove(0)
    }

    fn at() -> Time {
        Time::new(jiff::Timestamp::UNIX_EPOCH, &jiff::tz::TimeZone::UTC)
    }

    #[test]
    fn are_you_there_is_answered_to_the_requester_with_its_request_id() {
        let request = request(
            "CFX.AreYouThereRequest",
            serde_json::json!({"CFXHandle": "Panasonic.BM221.placer1"}),
        );
        let answer = endpoint().answer(&request, at()).unwrap().to_json();
        assert_eq!(answer["MessageName"], "CFX.AreYouThereResponse");
        assert_eq!(answer["Target"], "MES.Line1.Host");
        assert_eq!(answer["RequestID"], "request-42");
        assert_eq!(answer["Source"], "Panasonic.BM221.placer1");
        assert_eq!(answer["MessageBody"]["Result"]["Result"], "Success");
        assert_eq!(
            answer["MessageBody"]["RequestNetworkUri"],
            "amqp://127.0.0.1:5673/"
        );
    }

    #[test]
    fn who_is_there_is_answered_only_for_the_topics_it_publishes() {
        let asked = |topic: &str| {
            request(
                "CFX.WhoIsThereRequest",
                serde_json::json!({
                    "SupportedTopicQueryType": "All",
                    "SupportedTopics": [{"TopicName": topic, "TopicSupportType": "Publisher", "SupportedMessages": []}]
                }),
            )
        };
        let e = endpoint();
        assert!(e.answer(&asked("CFX.ResourcePerformance"), at()).is_some());
        assert!(e.answer(&asked("CFX.Materials.Storage"), at()).is_none());
        let everyone = request("CFX.WhoIsThereRequest", serde_json::json!({}));
        assert!(e.answer(&everyone, at()).is_some());
    }

    #[test]
    fn endpoint_information_says_what_the_machine_is_and_other_requests_are_not_supported() {
        let e = endpoint();
        let info = e
            .answer(
                &request("CFX.GetEndpointInformationRequest", serde_json::json!({})),
                at(),
            )
            .unwrap()
            .to_json();
        let body = &info["MessageBody"]["EndpointInformation"];
        assert_eq!(body["Vendor"], "Panasonic");
        assert_eq!(body["CFXVersion"], "2.1");
        let other = e
            .answer(
                &request(
                    "CFX.Production.GetActiveRecipeRequest",
                    serde_json::json!({}),
                ),
                at(),
            )
            .unwrap()
            .to_json();
        assert_eq!(other["MessageName"], "CFX.NotSupportedResponse");
        assert_eq!(other["MessageBody"]["RequestResult"]["Result"], "Failed");
        assert_eq!(other["RequestID"], "request-42");
        // Not a request: nothing to answer.
        let event = request("CFX.Heartbeat", serde_json::json!({}));
        assert!(e.answer(&event, at()).is_none());
    }
}
