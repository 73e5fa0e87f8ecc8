//! IPC-CFX (IPC-2591): a placement machine of the cell as a CFX endpoint. The messages'
//! JSON and AMQP properties are the `cfx` crate's; [`station`] turns what the change
//! stream says of one machine into the CFX messages it publishes, sans IO.
//!
//! Not built yet (issue #39): the AMQP 1.0 transport to a broker, the endpoint's request
//! listener, the catch-up from the history after an outage, the `[cfx]` table and the
//! `cellbus cfx` commands. Until then nothing starts a station.

pub mod station;
