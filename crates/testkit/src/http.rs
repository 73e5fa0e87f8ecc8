//! A plain HTTP/1.1 GET for tests of a running gateway: no client library between the test
//! and the server's bytes.

use std::net::SocketAddr;

use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// GETs `path` from `addr` over a fresh connection (`Connection: close`): the whole
/// response, head and body.
///
/// # Panics
///
/// When the server cannot be reached or the connection fails.
pub async fn get_response(addr: SocketAddr, path: &str) -> String {
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream
        .write_all(
            format!("GET {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n").as_bytes(),
        )
        .await
        .unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).await.unwrap();
    response
}
