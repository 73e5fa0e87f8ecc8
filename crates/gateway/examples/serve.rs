//! Runs the gateway without the CLI: `cargo run -p gateway --example serve -- [--listen
//! ADDR] [--data DIR] [--config FILE] [--allow-writes]`. Without `--config` it serves the
//! demo cell. Stops on Ctrl-C. It has the gateway crate's own interfaces (MQTT), not OPC UA.

use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut options = gateway::ServeOptions::default();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = || {
            args.next()
                .ok_or_else(|| anyhow::anyhow!("{arg} needs a value"))
        };
        match arg.as_str() {
            "--listen" => options.listen = value()?.parse()?,
            "--data" => options.data_dir = PathBuf::from(value()?),
            "--config" => options.config = Some(PathBuf::from(value()?)),
            "--allow-writes" => options.allow_writes = true,
            other => anyhow::bail!(
                "unknown argument {other:?}; use --listen, --data, --config, --allow-writes"
            ),
        }
    }
    tokio::runtime::Runtime::new()?.block_on(gateway::serve(
        options,
        &gateway::plugins::builtin(),
        async {
            let _ = tokio::signal::ctrl_c().await;
        },
    ))
}
