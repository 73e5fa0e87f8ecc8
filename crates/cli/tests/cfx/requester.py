"""A CFX requester nobody here wrote, as the SDK's request processor expects one:
python-qpid-proton connects to an endpoint's listener (argv[1], amqp://IP:PORT), attaches a
receiver whose target is its reply-to address and a sender to the endpoint's handle
(argv[2]), and sends one request per message name given after that, with `reply-to` and
`correlation-id` = its RequestID. Prints one JSON line per answer (correlation id, the
AMQP properties and the body), then exits when every request has its answer (or after
60 s, exit 1).
"""

import json
import sys
import uuid

from proton import Message
from proton.handlers import MessagingHandler
from proton.reactor import Container

REPLY_TO = "cfx-test-replies"


def text(value):
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


class Requester(MessagingHandler):
    def __init__(self, url, handle, names):
        super().__init__()
        self.url, self.handle, self.names = url, handle, names
        self.sent, self.answered = False, 0

    def on_start(self, event):
        event.container.schedule(60, self)
        connection = event.container.connect(self.url)
        event.container.create_receiver(connection, source=self.handle, target=REPLY_TO)
        self.sender = event.container.create_sender(connection, target=self.handle)

    def on_timer_task(self, event):
        print("no answer to every request within 60 s", file=sys.stderr, flush=True)
        sys.exit(1)

    def on_sendable(self, event):
        if self.sent:
            return
        self.sent = True
        for number, name in enumerate(self.names):
            request_id = f"request-{number}"
            envelope = {
                "MessageName": name,
                "Version": "2.1",
                "TimeStamp": "2026-11-29T12:00:00.0000000+00:00",
                "UniqueID": str(uuid.uuid4()),
                "Source": "MES.Line1.Host",
                "Target": self.handle,
                "RequestID": request_id,
                "MessageBody": {"$type": f"{name}, CFX", "CFXHandle": self.handle},
            }
            event.sender.send(
                Message(
                    body=json.dumps(envelope).encode("utf-8"),
                    reply_to=REPLY_TO,
                    correlation_id=request_id,
                    subject=f"MES.Line1.Host.{name}",
                )
            )

    def on_message(self, event):
        message = event.message
        body = message.body
        if isinstance(body, memoryview):
            body = bytes(body)
        if isinstance(body, bytes):
            body = body.decode("utf-8")
        print(
            json.dumps(
                {
                    "correlation_id": text(message.correlation_id),
                    "to": message.address,
                    "subject": message.subject,
                    "properties": {k: text(v) for k, v in (message.properties or {}).items()},
                    "body": json.loads(body),
                }
            ),
            flush=True,
        )
        self.answered += 1
        if self.answered == len(self.names):
            event.connection.close()
            event.container.stop()


Container(Requester(sys.argv[1], sys.argv[2], sys.argv[3:])).run()
