"""A CFX source nobody here wrote, for `cellbus cfx sub URL`: python-qpid-proton listening
for AMQP 1.0 without a broker (prints `listening on PORT`); to each link attached to
receive from it, it sends two CFX envelopes (a batch of two in one message, then one
alone), as an endpoint publishing through a broker's address would. Runs until killed.
"""

import json

from proton import Message
from proton.handlers import MessagingHandler
from proton.reactor import Container


def envelope(name, body):
    return {
        "MessageName": name,
        "Version": "2.1",
        "TimeStamp": "2026-11-29T12:00:00.0000000+00:00",
        "UniqueID": "3de0cfce-42f4-4302-982b-96dba4ec3de0",
        "Source": "SMTPlus.Model_21232.SN23123",
        "Target": None,
        "RequestID": None,
        "MessageBody": dict({"$type": f"{name}, CFX"}, **body),
    }


class Source(MessagingHandler):
    def __init__(self):
        super().__init__()
        self.served = set()

    def on_start(self, event):
        acceptor = event.container.listen("127.0.0.1:0")
        port = acceptor._selectable._delegate.getsockname()[1]
        print(f"listening on {port}", flush=True)

    def on_sendable(self, event):
        if event.sender in self.served:
            return
        self.served.add(event.sender)
        batch = [
            envelope("CFX.ResourcePerformance.StationOffline", {}),
            envelope("CFX.ResourcePerformance.StationOnline", {"OfflineDuration": "00:23:00"}),
        ]
        event.sender.send(Message(body=json.dumps(batch).encode("utf-8"), subject="batch"))
        alone = envelope("CFX.EndpointShuttingDown", {"CFXHandle": "SMTPlus.Model_21232.SN23123"})
        event.sender.send(Message(body=json.dumps(alone).encode("utf-8"), subject="alone"))


Container(Source()).run()
