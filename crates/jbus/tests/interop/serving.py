"""What the pymodbus servers of cellbus's interoperability tests share."""


async def serve(server, scheme):
    """Starts `server` on its free port, prints `listening on SCHEME://127.0.0.1:PORT` (what
    the Rust side waits for) and serves until killed."""
    await server.serve_forever(background=True)
    port = server.transport.sockets[0].getsockname()[1]
    print(f"listening on {scheme}://127.0.0.1:{port}", flush=True)
    await server.serving
