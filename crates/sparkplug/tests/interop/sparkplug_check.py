#!/usr/bin/env python3
"""An independent Sparkplug B decoder for cellbus's interoperability test.

Compiles the spec's schema (crates/sparkplug/proto/sparkplug_b.proto) with
`python -m grpc_tools.protoc` into a temporary directory, subscribes with paho-mqtt to
spBv1.0/GROUP/# on 127.0.0.1:PORT, and collects an NBIRTH, the DBIRTHs after it and at
least one DDATA of a device born after it, within a time limit. Decodes them with the
generated classes only (no cellbus code) and prints:

    subscribed                       once the broker acknowledged the subscription
    {"node": {...}, "devices": {...}, "data": [...]}   the summary, one JSON line

where node and each device map metric name -> {"datatype": code, "alias": n,
"unit": engUnit or null, "value": value or null}, and data lists each DDATA as
{"device", "seq", "metrics": [{"alias", "name" (from the births, or null), "value"}]}.

Exits 1 with a message on stderr when the broker cannot be reached, a payload does not
decode, or the messages do not come in time.

Usage: sparkplug_check.py PORT [--group cellbus] [--limit SECONDS]
"""

import argparse
import json
import math
import os
import queue
import subprocess
import sys
import tempfile
import time

import paho.mqtt.client as mqtt

PROTO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "proto", "sparkplug_b.proto")


def fail(message):
    print(f"sparkplug_check: {message}", file=sys.stderr, flush=True)
    sys.exit(1)


def compile_schema(out_dir):
    """The generated module for the spec's .proto, compiled by grpc_tools.protoc."""
    proto_dir, proto_file = os.path.split(os.path.normpath(PROTO))
    done = subprocess.run(
        [sys.executable, "-m", "grpc_tools.protoc", f"-I{proto_dir}", f"--python_out={out_dir}", proto_file],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        fail(f"protoc could not compile {PROTO}: {done.stderr.strip()}")
    sys.path.insert(0, out_dir)
    try:
        import sparkplug_b_pb2  # noqa: E402  (generated just now)
    finally:
        sys.path.remove(out_dir)
    return sparkplug_b_pb2


def plain(value):
    """A JSON-safe number: NaN and infinities become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def metric_value(metric):
    if metric.is_null:
        return None
    field = metric.WhichOneof("value")
    if field is None:
        return None
    value = getattr(metric, field)
    if isinstance(value, bytes):
        return value.hex()
    if field == "int_value" and metric.datatype in (1, 2, 3):
        # Signed 8/16/32-bit values travel as their two's complement bits in a uint32.
        value = value - (1 << 32) if value >= 1 << 31 else value
    if field == "long_value" and metric.datatype == 4:
        value = value - (1 << 64) if value >= 1 << 63 else value
    return plain(value)


def unit_of(metric):
    props = metric.properties
    for key, value in zip(props.keys, props.values):
        if key == "engUnit":
            return value.string_value
    return None


def birth_table(payload):
    return {
        m.name: {
            "datatype": m.datatype if m.HasField("datatype") else None,
            "alias": m.alias if m.HasField("alias") else None,
            "unit": unit_of(m),
            "value": metric_value(m),
        }
        for m in payload.metrics
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("port", type=int)
    parser.add_argument("--group", default="cellbus")
    parser.add_argument("--limit", type=float, default=60.0, help="seconds to wait for everything")
    args = parser.parse_args()

    # The generated module is imported at once; its directory goes when the import is done.
    with tempfile.TemporaryDirectory(prefix="sparkplug-py-") as out_dir:
        pb = compile_schema(out_dir)

    inbox = queue.Queue()
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"sparkplug-check-{os.getpid()}")
    topic_filter = f"spBv1.0/{args.group}/#"

    def on_connect(client, _userdata, _flags, reason_code, _properties):
        if reason_code.is_failure:
            inbox.put(("error", f"the broker refused the connection: {reason_code}"))
        else:
            client.subscribe(topic_filter, qos=1)

    def on_subscribe(_client, _userdata, _mid, reason_codes, _properties):
        if any(rc.is_failure for rc in reason_codes):
            inbox.put(("error", f"the broker refused the subscription to {topic_filter}"))
        else:
            inbox.put(("subscribed", None))

    def on_message(_client, _userdata, message):
        inbox.put(("message", (message.topic, message.payload)))

    client.on_connect = on_connect
    client.on_subscribe = on_subscribe
    client.on_message = on_message
    try:
        client.connect("127.0.0.1", args.port, keepalive=30)
    except OSError as e:
        fail(f"cannot connect to the broker on 127.0.0.1:{args.port}: {e}")
    client.loop_start()

    node = None
    devices = {}
    data = []
    deadline = time.monotonic() + args.limit
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            missing = "an NBIRTH" if node is None else ("a DBIRTH" if not devices else "a DDATA of a born device")
            fail(f"no {missing} on {topic_filter} within {args.limit} s (births: {sorted(devices)})")
        try:
            what, body = inbox.get(timeout=left)
        except queue.Empty:
            continue
        if what == "error":
            fail(body)
        if what == "subscribed":
            print("subscribed", flush=True)
            continue
        topic, raw = body
        levels = topic.split("/")
        if len(levels) < 4:
            continue
        kind = levels[2]
        if kind not in ("NBIRTH", "DBIRTH", "DDATA"):
            continue
        payload = pb.Payload()
        try:
            payload.ParseFromString(raw)
        except Exception as e:  # the decoder's own error, whatever its class
            fail(f"{topic}: not a Sparkplug B payload: {e}")
        if kind == "NBIRTH":
            node = birth_table(payload)
            devices = {}
            data = []
        elif node is None:
            continue  # wait for a node birth: what came before it belongs to no session we saw
        elif kind == "DBIRTH":
            devices[levels[4]] = birth_table(payload)
        elif kind == "DDATA":
            device = levels[4]
            names = {v["alias"]: k for k, v in devices.get(device, {}).items()}
            data.append(
                {
                    "device": device,
                    "seq": payload.seq if payload.HasField("seq") else None,
                    "metrics": [
                        {
                            "alias": m.alias if m.HasField("alias") else None,
                            "name": m.name if m.HasField("name") else names.get(m.alias),
                            "value": metric_value(m),
                        }
                        for m in payload.metrics
                    ],
                }
            )
            if device in devices:
                break
    client.loop_stop()
    client.disconnect()
    print(json.dumps({"node": node, "devices": devices, "data": data}, allow_nan=False), flush=True)


if __name__ == "__main__":
    main()
