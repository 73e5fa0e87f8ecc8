"""An IPC-CFX consumer nobody here wrote: python-qpid-proton (pinned in scripts/test)
listening for AMQP 1.0 without a broker, as an MES's CFX receiver would; or, given
`--from URL ADDRESS`, a consumer of a broker's queue (connecting again whenever the
broker closes the connection or is away, as a broker restart does).

Listening, it prints `listening on PORT` (a free loopback port, or the one given as its
argument). Then one JSON line per message: the link's address, the AMQP properties and
application properties, and the body (the CFX JSON, parsed). Accepts every message. Runs
until killed.
"""

import json
import sys
import time

from proton.handlers import MessagingHandler
from proton.reactor import Container


def text(value):
    """An AMQP value as JSON can carry it."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


class Receiver(MessagingHandler):
    started = False

    def on_start(self, event):
        if sys.argv[1:2] == ["--from"]:
            url, address = sys.argv[2], sys.argv[3]
            connection = event.container.connect(url, allowed_mechs="ANONYMOUS")
            event.container.create_receiver(connection, address)
            if not Receiver.started:
                print(f"receiving from {address}", flush=True)
                Receiver.started = True
            return
        port = sys.argv[1] if len(sys.argv) > 1 else "0"
        acceptor = event.container.listen(f"127.0.0.1:{port}")
        # proton 0.40 keeps the listening socket here; the port 0 asked for is now known.
        port = acceptor._selectable._delegate.getsockname()[1]
        print(f"listening on {port}", flush=True)

    def on_message(self, event):
        message = event.message
        body = message.body
        if isinstance(body, memoryview):
            body = bytes(body)
        if isinstance(body, bytes):
            body = body.decode("utf-8")
        target = event.link.remote_target
        source = event.link.remote_source
        print(
            json.dumps(
                {
                    "address": target.address if target and target.address else source.address,
                    "message_id": text(message.id),
                    "subject": message.subject,
                    "content_type": text(message.content_type),
                    "reply_to": message.reply_to,
                    "creation_time": message.creation_time,
                    "durable": message.durable,
                    "properties": {k: text(v) for k, v in (message.properties or {}).items()},
                    "body": json.loads(body),
                }
            ),
            flush=True,
        )


if sys.argv[1:2] == ["--from"]:
    # A broker that stops closes the connection with an error, which ends proton's run.
    while True:
        try:
            Container(Receiver()).run()
        except Exception as e:  # noqa: BLE001 - a consumer outlives its broker
            print(f"consumer: {e}", file=sys.stderr, flush=True)
        time.sleep(0.5)
else:
    Container(Receiver()).run()
