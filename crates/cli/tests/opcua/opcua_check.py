"""An independent OPC UA client (Python asyncua) against `cellbus serve --opcua`.

    opcua_check.py read  OPC_URL HTTP_ADDR
    opcua_check.py write OPC_URL HTTP_ADDR DATA_DIR PASSWORD
    opcua_check.py down  OPC_URL DEVICE POINT
    opcua_check.py anonymous-refused OPC_URL
    opcua_check.py flood OPC_URL HTTP_ADDR COUNT
    opcua_check.py items OPC_URL HTTP_ADDR CAP
    opcua_check.py alarm OPC_URL HTTP_ADDR PASSWORD DEVICE
    opcua_check.py reload OPC_URL REMOVED ADDED CHANGED DESCRIPTION LINES

`read`: browses Objects/Cell and compares every device and point with /api/devices
(data type, description, unit, range, access, enumeration labels); subscribes to the point that changes most
with its poll period as sampling interval and gets every change /api/history then holds,
with its value, status and source time, in order, each within a poll period (+2 s) of
its read; sees the session in /healthz and /metrics meanwhile; and is refused a write (no
--allow-writes). `write`: connects with
Basic256Sha256 SignAndEncrypt and a client certificate (refused until the certificate is
moved from the server's rejected folder to its trusted folder), logs in as `operator`,
is refused an out-of-range write, writes a valid one, finds both in /api/audit with its
own address (`from 127.0.0.1:PORT`), receives
the write's event (message, severity, source, time as in /api/events) on event
subscriptions to the device's object (CellbusEventType: its Kind and Fields too) and to
the Server object (BaseEventType), and compares
HistoryRead raw (whole, in pages of numValuesPerNode 2 with continuation points, with
returnBounds) and Average with /api/history.

`down`: subscribes anonymously to DEVICE's POINT, prints `subscribed` once it is Good, and
waits for it to turn Bad (the test stops the device meanwhile), with no value.
`anonymous-refused`: an anonymous session must be refused.
`flood`: COUNT clients (security None) each create a session and never activate it, more
than the server's 100 sessions; the server must refuse those beyond its per-address cap
(/healthz, /metrics), and a legitimate client must still connect, read and get a value on
a subscription within 40 s (the sessions, asking for an hour, would otherwise hold every
slot for the server's session timeout, a minute); the waiting sessions are closed, those
whose client stays (`not_activated`) and the one whose client leaves (`abandoned`).
`items`: one client asks for CAP + 20 monitored items (the server's `max_monitored_items`
is CAP), CAP - 50 on a device's Status and 70 on the server's own CurrentTime (namespace
0): the 20 beyond get Bad_TooManyMonitoredItems, /healthz and /metrics count them, the
server still answers, and deleting items frees their places.

`alarm`: an anonymous session (security None) sees the methods of
Objects/Gateway/Alarms not executable for it and is refused Acknowledge
(Bad_UserAccessDenied); `operator` (Basic256Sha256 SignAndEncrypt, its certificate
trusted as it comes) finds DEVICE:down in the device's Alarms folder, subscribes to the
device's events and prints `subscribed` (the test stops the device meanwhile), receives
the alarm_raised event, sees the alarm's State turn unacknowledged, acknowledges it with a
comment, receives the alarm_changed event, is refused a second acknowledgement and an
unknown alarm, shelves it (a shelving of 0 s refused) and unshelves it (twice: refused),
and finds the acknowledgement in /api/alarms/journal with the comment and by `opcua user
operator from 127.0.0.1:PORT` (the client's own port).

`reload`: browses Objects/Cell anonymously (security None), keeps the node ids of
everything under REMOVED (its points and their properties, Status, Error, its Production
and Alarms folders, its alarms' objects), subscribes to the Gateway object's events and
prints `browsed` (the test rewrites the configuration and sends SIGHUP meanwhile); on the
config_reloaded event it browses again and finds ADDED with its points (their data type
read), CHANGED described as DESCRIPTION, the Gateway's Lines as LINES (comma-separated),
and every node of REMOVED gone: a read, a write and a monitored item on it are refused
with Bad_NodeIdUnknown.

Prints `ok: ...` lines; any failure raises (exit 1). Every wait is bounded.
"""

import asyncio
import json
import os
import shutil
import sys
import tempfile
import time
import urllib.request
from datetime import datetime, timedelta, timezone

from asyncua import Client, ua
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

LIMIT = 30.0  # seconds for any one wait
# Seconds for a whole script: four scripts run at once on a 2-core machine, each signing
# and encrypting in Python; under the Rust test's own bound (180 s).
SCRIPT_LIMIT = 170.0


def http(addr, path):
    with urllib.request.urlopen(f"http://{addr}{path}", timeout=LIMIT) as r:
        return json.loads(r.read())


def ms(text):
    """Milliseconds since 1970 of the API's ISO time."""
    return round(datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp() * 1000)


def iso(t):
    return t.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


STARTED = time.monotonic()


def ok(words):
    # With the seconds since the start: a run that ends on the overall bound shows where
    # the time went.
    print(f"ok: {words} ({time.monotonic() - STARTED:.1f} s)", flush=True)


async def cell_tree(client):
    """{device id: (line, {browse name: node})} under Objects/Cell."""
    ns = await client.get_namespace_index("urn:cellbus:cell")
    cell = await client.nodes.objects.get_child(f"{ns}:Cell")
    tree = {}
    for line in await cell.get_children():
        line_name = (await line.read_browse_name()).Name
        for device in await line.get_children():
            name = (await device.read_browse_name()).Name
            children = {}
            for child in await device.get_children():
                children[(await child.read_browse_name()).Name] = child
            # The machine state and OEE points are in the device's Production folder.
            if "Production" in children:
                for child in await children["Production"].get_children():
                    children[(await child.read_browse_name()).Name] = child
            tree[name] = (line_name, children)
    return ns, tree


DATATYPES = {"numeric": ua.VariantType.Double, "enum": ua.VariantType.Int32, "text": ua.VariantType.String}


async def check_tree(client, devices):
    ns, tree = await cell_tree(client)
    assert set(tree) == {d["id"] for d in devices}, (sorted(tree), [d["id"] for d in devices])
    points = enums = 0
    for d in devices:
        line, children = tree[d["id"]]
        assert line == d["line"], (d["id"], line, d["line"])
        names = {p["id"].split(".", 1)[1] for p in d["points"]}
        folders = {"Production"} if "machine_state" in names else set()
        assert set(children) == names | {"Status", "Error", "Alarms"} | folders, (d["id"], sorted(children))
        alarms = {(await a.read_browse_name()).Name for a in await children["Alarms"].get_children()}
        assert f"{d['id']}:down" in alarms, (d["id"], sorted(alarms))
        status = await children["Status"].read_value()
        assert status in ("up", "down", "backed off", "connecting"), status
        for p in d["points"]:
            node = children[p["id"].split(".", 1)[1]]
            data_type = await node.read_data_type_as_variant_type()
            assert data_type == DATATYPES[p["kind"]["type"]], (p["id"], data_type)
            description = (await node.read_description()).Text
            assert description == p["name"], (p["id"], description)
            access = await node.read_attribute(ua.AttributeIds.AccessLevel)
            writable = bool(access.Value.Value & ua.AccessLevel.CurrentWrite.mask)
            assert writable == (p["writable"] is not None), (p["id"], access.Value.Value)
            properties = {(await c.read_browse_name()).Name: c for c in await node.get_properties()}
            if p["unit"]:
                eu = await properties["EngineeringUnits"].read_value()
                assert eu.DisplayName.Text == p["unit"], (p["id"], eu)
            else:
                assert "EngineeringUnits" not in properties, p["id"]
            if p["kind"]["type"] == "numeric" and p["writable"]:
                r = await properties["EURange"].read_value()
                assert (r.Low, r.High) == (p["writable"]["min"], p["writable"]["max"]), (p["id"], r)
            if p["kind"]["type"] == "enum":
                states = [(st["value"], st["label"]) for st in p["kind"]["states"]]
                values = await properties["EnumValues"].read_value()
                assert [(v.Value, v.DisplayName.Text) for v in values] == states, (p["id"], values)
                if [v for v, _ in states] == list(range(len(states))):
                    strings = await properties["EnumStrings"].read_value()
                    assert [t.Text for t in strings] == [l for _, l in states], (p["id"], strings)
                else:
                    assert "EnumStrings" not in properties, p["id"]
                enums += 1
            points += 1
    assert enums > 0, "the demo cell has enumeration points"
    production = sum(1 for d in devices if "Production" in tree[d["id"]][1])
    assert production > 0, "no device has a Production folder"
    await check_paths(client, ns, tree, devices)
    ok(f"{len(devices)} devices and {points} points match /api/devices ({enums} enumerations with EnumValues, {production} Production folders)")
    return ns, tree


async def check_paths(client, ns, tree, devices):
    """A device's references two at a time (BrowseNext) are all of them, its folders and
    variables then its points (the server's two node managers); a browse path reaches a
    point's property, and a point's parent is its device."""
    d = next(d for d in devices if "Production" in tree[d["id"]][1])
    device = client.get_node(ua.NodeId(d["id"], ns))
    whole = [
        r.NodeId
        for r in await device.get_references(ua.ObjectIds.HierarchicalReferences, ua.BrowseDirection.Forward)
    ]
    desc = ua.BrowseDescription()
    desc.NodeId = device.nodeid
    desc.BrowseDirection = ua.BrowseDirection.Forward
    desc.ReferenceTypeId = ua.NodeId(ua.ObjectIds.HierarchicalReferences)
    desc.IncludeSubtypes = True
    desc.ResultMask = ua.BrowseResultMask.All
    params = ua.BrowseParameters()
    params.View.Timestamp = ua.get_win_epoch()
    params.RequestedMaxReferencesPerNode = 2
    params.NodesToBrowse = [desc]
    [result] = await client.uaclient.browse(params)
    paged, pages = list(result.References), 1
    while result.ContinuationPoint:
        more = ua.BrowseNextParameters()
        more.ReleaseContinuationPoints = False
        more.ContinuationPoints = [result.ContinuationPoint]
        [result] = await client.uaclient.browse_next(more)
        assert len(result.References) <= 2, result
        paged.extend(result.References)
        pages += 1
    # The same references, each once (async-opcua hands its own pages back in another order).
    got = sorted(r.NodeId.to_string() for r in paged)
    assert got == sorted(n.to_string() for n in whole) and len(set(got)) == len(got), (got, whole)
    assert len(whole) > 4 and pages == (len(whole) + 1) // 2, (len(whole), pages)
    ok(f"{d['id']}'s {len(whole)} references came two at a time in {pages} pages")
    line = tree[d["id"]][0]
    p = next(p for p in d["points"] if p["unit"] and ua.NodeId(p["id"], ns) in whole)
    name = p["id"].split(".", 1)[1]
    eu = await client.nodes.objects.get_child(
        [f"{ns}:Cell", f"{ns}:{line}", f"{ns}:{d['id']}", f"{ns}:{name}", "0:EngineeringUnits"]
    )
    assert eu.nodeid == ua.NodeId(f"{p['id']}/EngineeringUnits", ns), eu.nodeid
    assert (await eu.read_value()).DisplayName.Text == p["unit"]
    parent = await client.get_node(ua.NodeId(p["id"], ns)).get_parent()
    assert parent.nodeid == device.nodeid, parent
    ok(f"the browse path Cell/{line}/{d['id']}/{name}/EngineeringUnits gives {eu.nodeid.Identifier}, whose point's parent is {d['id']}")


class Changes:
    def __init__(self):
        self.seen = asyncio.Queue()

    def datachange_notification(self, node, val, data):
        self.seen.put_nowait((node, val, data))


class Events:
    def __init__(self):
        self.seen = asyncio.Queue()

    def event_notification(self, event):
        self.seen.put_nowait(event)


async def subscribe_events(client, node, event_type=ua.ObjectIds.BaseEventType, queue=0):
    handler = Events()
    sub = await client.create_subscription(100, handler)
    # Without asyncua's where clause (EventType InList [the type, its subtypes]): the
    # server's filter (async-opcua 0.19) compares no NodeIds in InList, so that clause
    # matches nothing; the select clauses alone pick the type's fields. A `queue` of 0 keeps
    # only the last event of a publishing interval.
    await sub.subscribe_events(node, event_type, where_clause_generation=False, queuesize=queue)
    return sub, handler


async def event_of(handler, source, message):
    """The first event from `source` with `message` (bounded: LIMIT)."""
    others = []
    try:
        while True:
            event = await asyncio.wait_for(handler.seen.get(), LIMIT)
            if event.SourceName == source and event.Message.Text == message:
                return event
            others.append((event.SourceName, event.Message.Text))
    except asyncio.TimeoutError:
        raise AssertionError(f"no event {message!r} from {source}; others: {others}") from None


QUALITY = {"good": "Good", "stale": "UncertainLastUsableValue", "bad": "BadCommunicationError"}
MARGIN = 2.0  # seconds past a poll period a notification may take (the machine is shared)


def busiest_point(addr, devices):
    """The numeric point polled every second or faster that changed most lately."""
    now = datetime.now(timezone.utc)
    best, most = None, -1
    for d in devices:
        if d["status"] != "up":
            continue
        for p in d["points"]:
            if p["kind"]["type"] != "numeric" or p["period_ms"] > 1000:
                continue
            h = http(addr, f"/api/history?point={p['id']}&from={iso(now - timedelta(seconds=20))}&to={iso(now)}")
            if len(h["samples"]) > most:
                best, most = (d, p), len(h["samples"])
    assert best and most >= 2, f"no point of the demo cell changes often ({most} changes)"
    return best


def notified(data):
    """A notification as (source time in ms, value, status name)."""
    v = data.monitored_item.Value
    t = int(v.SourceTimestamp.replace(tzinfo=timezone.utc).timestamp() * 1000 + 0.5)
    value = v.Value.Value if v.StatusCode.is_good() or v.StatusCode.is_uncertain() else None
    return t, value, v.StatusCode.name


async def check_subscription(client, addr, tree, devices):
    """Every change the history holds over a few seconds arrives on a subscription with
    the point's poll period as sampling interval, with its value, status and source time,
    in order, within a poll period (plus a margin) of its source time."""
    d, p = busiest_point(addr, devices)
    node = tree[d["id"]][1][p["id"].split(".", 1)[1]]
    period = p["period_ms"]
    handler = Changes()
    sub = await client.create_subscription(100, handler)
    request = ua.MonitoredItemCreateRequest()
    request.ItemToMonitor = ua.ReadValueId(NodeId=node.nodeid, AttributeId=ua.AttributeIds.Value)
    request.MonitoringMode = ua.MonitoringMode.Reporting
    params = ua.MonitoringParameters()
    params.ClientHandle = 1
    params.SamplingInterval = float(period)
    params.QueueSize = 10
    params.DiscardOldest = True
    # OPC UA's default trigger; async-opcua 0.19 compares values only without a filter.
    params.Filter = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValue)
    request.RequestedParameters = params
    [created] = await sub.create_monitored_items([request])
    assert isinstance(created, int), f"the monitored item was refused: {created}"
    # The same point behind an absolute deadband wider than any change: only its initial
    # value arrives while the item above sees every change.
    banded = Changes()
    banded_sub = await client.create_subscription(100, banded)
    wide = ua.MonitoredItemCreateRequest()
    wide.ItemToMonitor = ua.ReadValueId(NodeId=node.nodeid, AttributeId=ua.AttributeIds.Value)
    wide.MonitoringMode = ua.MonitoringMode.Reporting
    wide_params = ua.MonitoringParameters()
    wide_params.ClientHandle = 2
    wide_params.SamplingInterval = float(period)
    wide_params.QueueSize = 10
    wide_params.DiscardOldest = True
    wide_params.Filter = ua.DataChangeFilter(
        Trigger=ua.DataChangeTrigger.StatusValue,
        DeadbandType=ua.DeadbandType.Absolute,
        DeadbandValue=1e12,
    )
    wide.RequestedParameters = wide_params
    [created] = await banded_sub.create_monitored_items([wide])
    assert isinstance(created, int), f"the deadband item was refused: {created}"
    # Health while subscribed: the session, the subscription and the item are counted.
    health = http(addr, "/healthz")["opcua"]
    assert health and health["sessions"] >= 1 and health["subscriptions"] >= 1, health
    assert health["monitored_items"] >= 1 and health["connections"] >= 1, health
    metrics = urllib.request.urlopen(f"http://{addr}/metrics", timeout=LIMIT).read().decode()
    sessions = [l for l in metrics.splitlines() if l.startswith("cellbus_opcua_sessions ")]
    assert sessions and int(sessions[0].split()[1]) >= 1, sessions
    ok(f"/healthz shows the OPC UA session: {health}")
    # The initial value, then changes until enough arrive (bounded).
    arrivals = []
    deadline = asyncio.get_running_loop().time() + 2 * LIMIT
    while len(arrivals) < 6:
        left = deadline - asyncio.get_running_loop().time()
        assert left > 0, f"only {len(arrivals)} notifications of {p['id']} in {2 * LIMIT} s"
        _, _, data = await asyncio.wait_for(handler.seen.get(), left)
        arrivals.append((time.time(), notified(data)))
    await sub.delete()
    await banded_sub.delete()
    assert banded.seen.qsize() == 1, \
        f"an absolute deadband of 1e12 let {banded.seen.qsize() - 1} changes of {p['id']} through"
    ok(f"an absolute deadband held back the {len(arrivals) - 1} changes of {p['id']}")
    # The initial value is the node's current value; the changes after it are compared.
    first_t = arrivals[0][1][0]
    changes = [n for _, n in arrivals[1:]]
    last_t = changes[-1][0]
    window = f"point={p['id']}&from={iso(datetime.fromtimestamp((first_t + 1) / 1000, timezone.utc))}" \
        f"&to={iso(datetime.fromtimestamp((last_t + 1) / 1000, timezone.utc))}"
    # The history commits in batches: poll until it holds the last change (bounded).
    while True:
        stored = [
            (ms(s["t"]), s["value"], QUALITY[s["quality"]])
            for s in http(addr, f"/api/history?{window}")["samples"]
        ]
        if stored and stored[-1][0] == last_t:
            break
        assert asyncio.get_running_loop().time() < deadline, (stored, changes)
        await asyncio.sleep(0.2)
    assert changes == stored, f"notifications {changes} differ from /api/history {stored}"
    for arrived, (t, _, _) in arrivals[1:]:
        late = arrived - t / 1000
        assert late <= period / 1000 + MARGIN, f"a change of {p['id']} arrived {late:.3f} s after it was read"
    worst = max(arrived - t / 1000 for arrived, (t, _, _) in arrivals[1:])
    ok(f"{len(changes)} changes of {p['id']} arrived on a subscription (sampling {period} ms) as "
       f"/api/history holds them, each within {worst:.3f} s of its read")


def writable_numeric(devices):
    for d in devices:
        for p in d["points"]:
            if p["kind"]["type"] == "numeric" and p["writable"] and d["status"] == "up":
                return d, p
    raise AssertionError("no writable numeric point on a device that is up")


async def read(url, addr):
    devices = http(addr, "/api/devices")["devices"]
    async with Client(url, timeout=LIMIT) as client:
        # The endpoints name the port clients reach (not the server's behind the relay).
        endpoints = await client.get_endpoints()
        urls = sorted({e.EndpointUrl.rstrip("/") for e in endpoints})
        assert urls == [url.rstrip("/")], (urls, url)
        ok(f"{len(endpoints)} endpoints, all at {urls[0]}")
        ns, tree = await check_tree(client, devices)
        good = 0
        for d in devices:
            for p in d["points"]:
                node = tree[d["id"]][1][p["id"].split(".", 1)[1]]
                rv = ua.ReadValueId()
                rv.NodeId, rv.AttributeId = node.nodeid, ua.AttributeIds.Value
                params = ua.ReadParameters()
                params.NodesToRead, params.TimestampsToReturn = [rv], ua.TimestampsToReturn.Both
                [value] = await client.uaclient.read(params)
                if value.StatusCode.is_good():
                    good += 1
                    # Good means a reading: a value and when the device was read (a point
                    # never read, or whose read failed, is Bad, never an empty Good).
                    assert value.SourceTimestamp is not None, (p["id"], value)
                    assert value.Value.VariantType != ua.VariantType.Null, (p["id"], value)
        assert good > 0, good
        ok(f"{good} points read Good, each with its value and source timestamp")
        await check_subscription(client, addr, tree, devices)
        d, p = writable_numeric(devices)
        node = tree[d["id"]][1][p["id"].split(".", 1)[1]]
        try:
            await node.write_value(ua.DataValue(ua.Variant(p["writable"]["min"], ua.VariantType.Double)))
            raise AssertionError("an anonymous write was accepted")
        except ua.UaStatusCodeError as e:
            assert e.code == ua.StatusCodes.BadUserAccessDenied, e
        ok(f"the write to {p['id']} was refused: BadUserAccessDenied")


async def secure_client(url, data_dir, password, cert_dir):
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    cert, key = os.path.join(cert_dir, "client.der"), os.path.join(cert_dir, "client.pem")
    uri = "urn:cellbus:test:asyncua"
    await setup_self_signed_certificate(
        key_file=__import__("pathlib").Path(key),
        cert_file=__import__("pathlib").Path(cert),
        app_uri=uri,
        host_name="localhost",
        cert_use=[ExtendedKeyUsageOID.CLIENT_AUTH],
        subject_attrs={"countryName": "FR", "organizationName": "cellbus test"},
    )
    client = Client(url, timeout=LIMIT)
    client.application_uri = uri
    client.set_user("operator")
    client.set_password(password)
    await client.set_security(
        SecurityPolicyBasic256Sha256, cert, key, mode=ua.MessageSecurityMode.SignAndEncrypt
    )
    return client


async def write(url, addr, data_dir, password):
    devices = http(addr, "/api/devices")["devices"]
    # Removed when this function's frame goes, or at the latest when the process exits.
    certs = tempfile.TemporaryDirectory(prefix="opcua-check-")
    cert_dir = certs.name
    client = await secure_client(url, data_dir, password, cert_dir)
    try:
        await client.connect()
        raise AssertionError("an untrusted client certificate was accepted")
    except Exception as e:  # the server refuses the channel
        ok(f"the untrusted client certificate was refused ({type(e).__name__})")
    rejected = os.path.join(data_dir, "opcua", "pki", "rejected")
    trusted = os.path.join(data_dir, "opcua", "pki", "trusted")
    files = os.listdir(rejected)
    assert len(files) == 1, files
    shutil.move(os.path.join(rejected, files[0]), os.path.join(trusted, files[0]))
    client = await secure_client(url, data_dir, password, cert_dir)
    async with client:
        ok("Basic256Sha256 SignAndEncrypt with the trusted certificate, user operator")
        ns, tree = await cell_tree(client)
        d, p = writable_numeric(devices)
        node = tree[d["id"]][1][p["id"].split(".", 1)[1]]
        too_high = p["writable"]["max"] + 1000
        try:
            await node.write_value(ua.DataValue(ua.Variant(float(too_high), ua.VariantType.Double)))
            raise AssertionError("an out-of-range write was accepted")
        except ua.UaStatusCodeError as e:
            assert e.code == ua.StatusCodes.BadOutOfRange, e
        ok(f"{too_high} for {p['id']} was refused: BadOutOfRange")
        # A Bad status or a timestamp in the written value: refused, never dropped on the way.
        within = float(p["writable"]["min"])
        for extra in [
            {"StatusCode": ua.StatusCode(ua.StatusCodes.BadInternalError)},
            {"SourceTimestamp": datetime.now(timezone.utc)},
        ]:
            try:
                await node.write_value(ua.DataValue(ua.Variant(within, ua.VariantType.Double), **extra))
                raise AssertionError(f"a write with {extra} was accepted")
            except ua.UaStatusCodeError as e:
                assert e.code == ua.StatusCodes.BadWriteNotSupported, e
        ok(f"a value with a Bad status or a timestamp for {p['id']} was refused: BadWriteNotSupported")
        # Text for a number: refused, and the audit names the point and the text as given.
        try:
            await node.write_value(ua.DataValue(ua.Variant("on", ua.VariantType.String)))
            raise AssertionError("text for a number was accepted")
        except ua.UaStatusCodeError as e:
            assert e.code == ua.StatusCodes.BadTypeMismatch, e
        row = http(addr, f"/api/audit?device={d['id']}")["audit"][0]
        assert (row["point"], row["new_value"], row["result"]) == (p["id"], "on", "refused"), row
        ok(f"text for {p['id']} was refused (BadTypeMismatch) and audited as {row['new_value']!r}")
        try:
            await client.get_node(f"ns={ns};s=nosuch.point").write_value(ua.DataValue(ua.Variant(1.0)))
            raise AssertionError("a write to a node that does not exist was accepted")
        except ua.UaStatusCodeError as e:
            assert e.code == ua.StatusCodes.BadNodeIdUnknown, e
        ok("a write to a node that does not exist: BadNodeIdUnknown")
        # A Float as typed: 1.23 is 1.2300000190734863 as a double, yet meant as 1.23.
        stepped = [
            (dd, pp) for dd in devices for pp in dd["points"]
            if dd["status"] == "up" and pp["writable"] and pp["writable"].get("step") == 0.01
            and pp["writable"]["min"] + 0.23 <= pp["writable"]["max"]
        ]
        assert stepped, "the demo cell has a writable point of step 0.01 (a sealer's heating factor)"
        dd, pp = stepped[0]
        target = tree[dd["id"]][1][pp["id"].split(".", 1)[1]]
        typed = round(pp["writable"]["min"] + 0.23, 2)
        await target.write_value(ua.DataValue(ua.Variant(typed, ua.VariantType.Float)))
        ok(f"the Float {typed} was written to {pp['id']} (step 0.01)")
        device_node = await node.get_parent()
        # The device object with the gateway's own event type (its Kind and Fields found by
        # browsing the type), the Server object with BaseEventType, as older clients do.
        ns = await client.get_namespace_index("urn:cellbus:cell")
        cell_event_type = client.get_node(ua.NodeId("CellbusEventType", ns))
        on_device = await subscribe_events(client, device_node, cell_event_type)
        on_server = await subscribe_events(client, client.nodes.server)
        value = float(p["writable"]["min"])
        await node.write_value(ua.DataValue(ua.Variant(value, ua.VariantType.Double)))
        ok(f"{value} written to {p['id']}")
        [logged] = http(addr, f"/api/events?kind=write&device={d['id']}")["events"]
        for where, (sub, handler) in [("device object", on_device), ("Server object", on_server)]:
            event = await event_of(handler, d["id"], logged["message"])
            assert event.Severity == 200, event.Severity
            assert event.SourceNode == device_node.nodeid, (event.SourceNode, device_node)
            assert event.EventType == cell_event_type.nodeid, event.EventType
            if where == "device object":
                assert event.Kind == "write", event.Kind
                assert json.loads(event.Fields) == logged["fields"], (event.Fields, logged)
                ok(f"the write's event carries its kind and fields: {event.Fields}")
            t = int(event.Time.replace(tzinfo=timezone.utc).timestamp() * 1000 + 0.5)
            assert t == ms(logged["t"]), (event.Time, logged["t"])
            assert event.ReceiveTime >= event.Time, (event.ReceiveTime, event.Time)
            assert event.EventId, event
            await sub.delete()
            ok(f"the write's event arrived on the {where}: {event.Message.Text!r}, severity {event.Severity}")
        audit = http(addr, f"/api/audit?device={d['id']}")["audit"]
        rows = [r for r in audit if "opcua user operator" in r["client"]]
        results = sorted({r["result"] for r in rows})
        assert {"refused", "attempted", "accepted"} <= set(results), audit
        host, port = client.uaclient.protocol.transport.get_extra_info("sockname")[:2]
        here = f"from {host}:{port})"
        assert all(r["client"].endswith(here) for r in rows), (here, [r["client"] for r in rows])
        ok(f"the audit log has the OPC UA user's rows: {', '.join(results)}; {rows[0]['client']}")

        # History: raw and Average against /api/history.
        now = datetime.now(timezone.utc)
        start = now.replace(second=0, microsecond=0) - timedelta(minutes=1)
        end = now + timedelta(seconds=1)
        h = http(addr, f"/api/history?point={p['id']}&from={iso(start)}&to={iso(end)}")
        raw = await node.read_raw_history(start, end, return_bounds=False)
        assert len(raw) == len(h["samples"]), (len(raw), len(h["samples"]))
        for mine, theirs in zip(raw, h["samples"]):
            t = int(mine.SourceTimestamp.replace(tzinfo=timezone.utc).timestamp() * 1000 + 0.5)
            assert t == ms(theirs["t"]), (t, theirs)
        ok(f"HistoryRead raw gives the {len(raw)} changes of /api/history")
        await check_paged_history(client, tree, addr, devices)
        step = 10_000
        h = http(addr, f"/api/history?point={p['id']}&from={iso(start)}&to={iso(end)}&step=10s")
        details = ua.ReadProcessedDetails()
        details.StartTime, details.EndTime, details.ProcessingInterval = start, end, step
        details.AggregateType = [ua.NodeId(ua.ObjectIds.AggregateFunction_Average)]
        result = await node.history_read(details)
        averages = {}
        for v in result.HistoryData.DataValues:
            if v.StatusCode.is_good():
                t = int(v.SourceTimestamp.replace(tzinfo=timezone.utc).timestamp() * 1000 + 0.5)
                averages[t] = v.Value.Value
        theirs = {ms(b["t"]): b["avg"] for b in h["buckets"]}
        assert set(averages) == set(theirs), (sorted(averages), sorted(theirs))
        for t, avg in theirs.items():
            assert abs(averages[t] - avg) < 1e-9, (t, averages[t], avg)
        ok(f"HistoryRead Average gives the {len(theirs)} buckets of /api/history")
        # Several nodes in one processed read, each with its own aggregate.
        aggregate = {
            name: ua.NodeId(getattr(ua.ObjectIds, f"AggregateFunction_{name}"))
            for name in ("Average", "Minimum", "Maximum")
        }

        async def read_processed(nodes, names):
            details = ua.ReadProcessedDetails()
            details.StartTime, details.EndTime, details.ProcessingInterval = start, end, step
            details.AggregateType = [aggregate[n] for n in names]
            params = ua.HistoryReadParameters()
            params.HistoryReadDetails = details
            params.TimestampsToReturn = ua.TimestampsToReturn.Both
            params.ReleaseContinuationPoints = False  # asyncua's default is True: no data
            params.NodesToRead = [ua.HistoryReadValueId(NodeId=n.nodeid, IndexRange="") for n in nodes]
            return await client.uaclient.history_read(params)

        def good(result):
            return {source_ms(v): v.Value.Value for v in result.HistoryData.DataValues if v.StatusCode.is_good()}

        low, high = await read_processed([node, node], ["Minimum", "Maximum"])
        assert low.StatusCode.is_good() and high.StatusCode.is_good(), (low.StatusCode, high.StatusCode)
        assert good(low) == {ms(b["t"]): b["min"] for b in h["buckets"]}, (good(low), h["buckets"])
        assert good(high) == {ms(b["t"]): b["max"] for b in h["buckets"]}, (good(high), h["buckets"])
        ok("one processed read gives each node its own aggregate (Minimum, Maximum)")
        # A node of the server's other node manager (the device's Alarms folder, an object
        # without history) ahead of them: async-opcua hands the points' manager its nodes
        # without their places, so the aggregates' places cannot be known and the points
        # are refused, never given another's.
        folder = tree[d["id"]][1]["Alarms"]
        first, low, high = await read_processed([folder, node, node], ["Average", "Minimum", "Maximum"])
        for result in (low, high):
            assert result.StatusCode.value == ua.StatusCodes.BadAggregateInvalidInputs, result.StatusCode
        ok(f"with a node not historized first and aggregates that differ: {first.StatusCode.name}, then refused")


async def read_pages(node, start, end, per_call, bounds):
    """Every value of a raw HistoryRead, following its continuation points; and the
    number of values of each call."""
    details = ua.ReadRawModifiedDetails()
    details.IsReadModified = False
    details.StartTime, details.EndTime = start, end
    details.NumValuesPerNode, details.ReturnBounds = per_call, bounds
    values, sizes, point = [], [], None
    while True:
        result = await node.history_read(details, point)
        result.StatusCode.check()
        page = result.HistoryData.DataValues or []
        values += page
        sizes.append(len(page))
        point = result.ContinuationPoint
        if not point:
            return values, sizes
        assert len(sizes) < 1000, "the continuation points never end"


def source_ms(v):
    return int(v.SourceTimestamp.replace(tzinfo=timezone.utc).timestamp() * 1000 + 0.5)


async def check_paged_history(client, tree, addr, devices):
    """numValuesPerNode with continuation points, and returnBounds, against /api/history,
    on the point that changes most."""
    d, p = busiest_point(addr, devices)
    node = tree[d["id"]][1][p["id"].split(".", 1)[1]]
    # A gateway that just started: wait (bounded) for a few changes to page through.
    deadline = asyncio.get_running_loop().time() + 2 * LIMIT
    while True:
        end = datetime.now(timezone.utc).replace(microsecond=0)
        start = end - timedelta(seconds=30)
        h = http(addr, f"/api/history?point={p['id']}&from={iso(start)}&to={iso(end)}")
        theirs = [ms(s["t"]) for s in h["samples"]]
        if len(theirs) >= 5:
            break
        assert asyncio.get_running_loop().time() < deadline, f"too few changes of {p['id']}: {theirs}"
        await asyncio.sleep(0.5)
    values, sizes = await read_pages(node, start, end, 2, False)
    assert [source_ms(v) for v in values] == theirs, (values, theirs)
    assert max(sizes) <= 2 and len(sizes) >= 2, sizes
    ok(f"HistoryRead raw with numValuesPerNode 2 gives the {len(values)} changes in {len(sizes)} calls")
    # A continuation point is for its node only.
    details = ua.ReadRawModifiedDetails()
    details.IsReadModified = False
    details.StartTime, details.EndTime = start, end
    details.NumValuesPerNode, details.ReturnBounds = 2, False
    first_page = await node.history_read(details)
    assert first_page.ContinuationPoint, first_page
    other = next(
        child for name, child in tree[d["id"]][1].items()
        if name not in ("Status", "Error", "Production", "Alarms") and child.nodeid != node.nodeid
    )
    elsewhere = await other.history_read(details, first_page.ContinuationPoint)
    assert elsewhere.StatusCode.value == ua.StatusCodes.BadContinuationPointInvalid, elsewhere.StatusCode
    ok("a continuation point sent with another node is refused: BadContinuationPointInvalid")
    # TimestampsToReturn: Server gives the server's times only; Neither is refused.
    for which in (ua.TimestampsToReturn.Server, ua.TimestampsToReturn.Neither):
        params = ua.HistoryReadParameters()
        params.HistoryReadDetails = details
        params.TimestampsToReturn = which
        params.ReleaseContinuationPoints = False  # asyncua's default is True: no data
        params.NodesToRead = [ua.HistoryReadValueId(NodeId=node.nodeid, IndexRange="")]
        [result] = await client.uaclient.history_read(params)
        if which == ua.TimestampsToReturn.Neither:
            assert result.StatusCode.value == ua.StatusCodes.BadTimestampsToReturnInvalid, result.StatusCode
        else:
            page = result.HistoryData.DataValues
            assert page and all(v.SourceTimestamp is None and v.ServerTimestamp for v in page), page
    ok("HistoryRead honours TimestampsToReturn (Server: server times only; Neither: refused)")
    # Bounds: from just after the first change to the last one, the first change is the
    # start bound and the last (at the end time) the end bound.
    first = datetime.fromtimestamp((theirs[0] + 1) / 1000, timezone.utc)
    last = datetime.fromtimestamp(theirs[-1] / 1000, timezone.utc)
    values, sizes = await read_pages(node, first, last, 2, True)
    assert [source_ms(v) for v in values] == theirs, (values, theirs)
    assert max(sizes) <= 2, sizes
    # Nothing after the end: Bad_BoundNotFound at the end time.
    later = datetime.now(timezone.utc).replace(microsecond=0) + timedelta(hours=1)
    values, _ = await read_pages(node, later, later + timedelta(hours=1), 0, True)
    assert len(values) == 2, values
    # The start bound: the latest change, from before the range.
    assert values[0].StatusCode.value != ua.StatusCodes.BadBoundNotFound, values[0]
    assert source_ms(values[0]) < later.timestamp() * 1000, values[0]
    assert values[1].StatusCode.value == ua.StatusCodes.BadBoundNotFound, values[1]
    assert source_ms(values[1]) == int((later + timedelta(hours=1)).timestamp() * 1000), values[1]
    ok("HistoryRead raw returnBounds gives the changes around the range, or BadBoundNotFound")


async def down(url, device, point):
    async with Client(url, timeout=LIMIT) as client:
        _, tree = await cell_tree(client)
        node = tree[device][1][point]
        handler = Changes()
        sub = await client.create_subscription(200, handler)
        await sub.subscribe_data_change([node])
        while True:
            _, _, data = await asyncio.wait_for(handler.seen.get(), 2 * LIMIT)
            if data.monitored_item.Value.StatusCode.is_good():
                break
        print("subscribed", flush=True)
        while True:
            _, val, data = await asyncio.wait_for(handler.seen.get(), 2 * LIMIT)
            value = data.monitored_item.Value
            if value.StatusCode.is_bad():
                assert val is None, f"a bad reading carries no value, got {val}"
                ok(f"{device}.{point} turned {value.StatusCode.name} when {device} stopped answering")
                break
            assert not value.StatusCode.is_good() or val is not None, value
        await sub.delete()


async def anonymous_refused(url):
    # The server answers (its endpoints are listed), but offers no anonymous login, or
    # refuses the session.
    endpoints = await Client(url, timeout=LIMIT).connect_and_get_server_endpoints()
    assert endpoints, "the server lists no endpoint"
    offered = [
        t.TokenType
        for e in endpoints
        for t in e.UserIdentityTokens
        if t.TokenType == ua.UserTokenType.Anonymous
    ]
    client = Client(url, timeout=LIMIT)
    try:
        await client.connect()
    except ua.UaError as e:
        ok(f"an anonymous session was refused ({len(offered)} anonymous policies offered): {e!r}")
        return
    await client.disconnect()
    raise AssertionError("an anonymous session was accepted")


async def never_activated(url, keep):
    """A client that creates a session and never activates it (asking for an hour); the
    client when `keep` and the session was created, else None (socket closed)."""
    client = Client(url, timeout=5)
    client.session_timeout = 3_600_000
    try:
        await client.connect_socket()
        await client.send_hello()
        await client.open_secure_channel()
        await client.create_session()
    except Exception:  # refused: the connection was closed, or the server said no
        client.disconnect_socket()
        return None
    if keep:
        return client
    client.disconnect_socket()
    return None


def opcua_state(addr):
    state = http(addr, "/healthz")["opcua"]
    assert state is not None, "/healthz has no OPC UA part"
    return state


async def eventually(what, check):
    """Polls `check` (no sleeping to wait: every 0.2 s up to LIMIT) until it is true."""
    deadline = time.monotonic() + LIMIT
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {LIMIT} s: {what}")
        await asyncio.sleep(0.2)


async def legitimate(url):
    """Connects anonymously (asking for an hour's session timeout, granted the server's
    session_timeout: 60 s), reads a point and gets a value on a subscription."""
    client = Client(url, timeout=10)
    client.session_timeout = 3_600_000
    async with client:
        assert client.session_timeout == 60_000, client.session_timeout
        _, tree = await cell_tree(client)
        _, children = next(iter(tree.values()))
        node = children["Status"]
        value = await node.read_data_value()
        assert value.Value is not None, value
        handler = Values()
        sub = await client.create_subscription(100, handler)
        await sub.subscribe_data_change(node)
        await asyncio.wait_for(handler.first.wait(), LIMIT)
        await sub.delete()


class Values:
    def __init__(self):
        self.first = asyncio.Event()

    def datachange_notification(self, node, val, data):
        self.first.set()


async def flood(url, addr, count):
    count = int(count)
    started = time.monotonic()
    kept = []
    for at in range(0, count, 20):
        batch = await asyncio.gather(
            *(never_activated(url, keep=True) for _ in range(min(20, count - at)))
        )
        kept.extend(c for c in batch if c is not None)
    # The sessions refused beyond the cap are closed on their channels as they come.
    await eventually("at most 10 sessions held", lambda: opcua_state(addr)["sessions"] <= 10)
    state = opcua_state(addr)
    refused = state["refused"]
    assert refused["sessions_per_address"] >= 1, state
    ok(
        f"{count} never-activated sessions asked for: {len(kept)} created, "
        f"{refused['sessions_per_address']} refused beyond the per-address cap, "
        f"{state['sessions']} held"
    )
    # A legitimate client gets in (retrying while the waiting sessions hold its address's
    # places) well within the minute the sessions would otherwise last.
    deadline = time.monotonic() + 40
    tries = 0
    while True:
        tries += 1
        try:
            await legitimate(url)
            break
        except Exception as e:
            if time.monotonic() > deadline:
                raise AssertionError(f"a legitimate client was locked out for 40 s: {e!r}")
            await asyncio.sleep(0.5)
    ok(
        f"a legitimate client connected, read and subscribed {time.monotonic() - started:.1f} s "
        f"after the flood began ({tries} tries)"
    )
    await eventually(
        "the waiting sessions are closed (not_activated)",
        lambda: opcua_state(addr)["refused"]["sessions_not_activated"] >= 1,
    )
    for client in kept:
        client.disconnect_socket()
    await never_activated(url, keep=False)
    await eventually(
        "a session whose client left unactivated is closed (abandoned)",
        lambda: opcua_state(addr)["refused"]["sessions_abandoned"] >= 1,
    )
    await eventually("every waiting session is gone", lambda: opcua_state(addr)["sessions"] == 0)
    with urllib.request.urlopen(f"http://{addr}/metrics", timeout=LIMIT) as r:
        metrics = r.read().decode()
    for reason in ["per_address", "not_activated", "abandoned"]:
        assert f'cellbus_opcua_sessions_refused_total{{reason="{reason}"}}' in metrics, reason
    state = opcua_state(addr)
    ok(f"waiting sessions closed and counted in /healthz and /metrics: {state['refused']}")


async def items(url, addr, cap):
    cap = int(cap)
    async with Client(url, timeout=LIMIT) as client:
        _, tree = await cell_tree(client)
        _, children = next(iter(tree.values()))
        node = children["Status"]
        sub = await client.create_subscription(500, Values())
        made = []
        refused = []
        # The cap counts every node's items: the server's own too.
        current_time = client.get_node(ua.ObjectIds.Server_ServerStatus_CurrentTime)
        for target, count in [(node, cap - 50), (current_time, 70)]:
            while count > 0:
                n = min(500, count)
                results = await sub.subscribe_data_change([target] * n, sampling_interval=1000)
                count -= n
                for r in results:
                    (made if isinstance(r, int) else refused).append(r)
        assert len(made) == cap, (len(made), cap)
        assert len(refused) == 20, refused[:3]
        assert all(r.value == ua.StatusCodes.BadTooManyMonitoredItems for r in refused), refused[:3]
        state = opcua_state(addr)
        assert state["monitored_items"] == cap, state
        assert state["refused"]["monitored_items"] == 20, state
        with urllib.request.urlopen(f"http://{addr}/metrics", timeout=LIMIT) as r:
            metrics = r.read().decode()
        assert "cellbus_opcua_monitored_items_refused_total 20" in metrics
        ok(f"{cap + 20} monitored items asked for: {cap} made, 20 refused BadTooManyMonitoredItems")
        # The server still answers, and deleted items free their places.
        await node.read_data_value()
        await sub.unsubscribe(made[:10])
        again = await sub.subscribe_data_change([node] * 10, sampling_interval=1000)
        assert all(isinstance(r, int) for r in again), again
        ok("the server still answers, and 10 items deleted made room for 10 more")


async def alarm_event(handler, kind, alarm_id):
    """The first CellbusEventType event of `kind` about alarm `alarm_id` (bounded)."""
    others = []
    try:
        while True:
            event = await asyncio.wait_for(handler.seen.get(), 2 * LIMIT)
            fields = json.loads(event.Fields) if event.Fields else {}
            if event.Kind == kind and fields.get("alarm") == alarm_id:
                return event, fields
            others.append((event.Kind, event.Message.Text))
    except asyncio.TimeoutError:
        raise AssertionError(f"no {kind} event of {alarm_id}; others: {others}") from None


async def value_becomes(node, what, wanted):
    """Reads `node` (every 0.2 s, up to LIMIT) until `wanted(value)` holds; the value."""
    deadline = time.monotonic() + LIMIT
    while True:
        value = await node.read_value()
        if wanted(value):
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {LIMIT} s: {what} (last {value!r})")
        await asyncio.sleep(0.2)


async def refused(call, code):
    """Awaits `call`, which must fail with status `code`."""
    try:
        await call
    except ua.UaStatusCodeError as e:
        assert e.code == code, (e, code)
        return
    raise AssertionError(f"accepted, not refused with {code:#x}")


async def alarm(url, addr, password, device):
    alarm_id = f"{device}:down"
    async with Client(url, timeout=LIMIT) as anonymous:
        ns = await anonymous.get_namespace_index("urn:cellbus:cell")
        methods = await anonymous.nodes.objects.get_child([f"{ns}:Gateway", f"{ns}:Alarms"])
        acknowledge = await methods.get_child(f"{ns}:Acknowledge")
        executable = await acknowledge.read_attribute(ua.AttributeIds.UserExecutable)
        assert executable.Value.Value is False, executable
        await refused(
            methods.call_method(acknowledge, alarm_id, "anonymous"), ua.StatusCodes.BadUserAccessDenied
        )
        ok("Objects/Gateway/Alarms.Acknowledge is not executable for and refused to an anonymous session: BadUserAccessDenied")

    certs = tempfile.TemporaryDirectory(prefix="opcua-check-")
    client = await secure_client(url, None, password, certs.name)
    async with client:
        ns, tree = await cell_tree(client)
        folder = tree[device][1]["Alarms"]
        node = await folder.get_child(f"{ns}:{alarm_id}")
        variables = {
            name: await node.get_child(f"{ns}:{name}")
            for name in ["State", "Active", "Acknowledged", "Priority", "ShelvedUntil"]
        }
        state = await variables["State"].read_value()
        assert state == "normal", state
        assert await variables["Active"].read_value() is False
        assert await variables["Priority"].read_value() == "high"
        ok(f"{alarm_id} in {device}'s Alarms folder: State {state}, Priority high")
        methods = await client.nodes.objects.get_child([f"{ns}:Gateway", f"{ns}:Alarms"])
        method = {
            name: await methods.get_child(f"{ns}:{name}") for name in ["Acknowledge", "Shelve", "Unshelve"]
        }
        executable = await method["Acknowledge"].read_attribute(ua.AttributeIds.UserExecutable)
        assert executable.Value.Value is True, executable
        device_node = await folder.get_parent()
        cell_event_type = client.get_node(ua.NodeId("CellbusEventType", ns))
        sub, handler = await subscribe_events(client, device_node, cell_event_type)
        states = Changes()
        state_sub = await client.create_subscription(100, states)
        await state_sub.subscribe_data_change(variables["State"])
        _, first, _ = await asyncio.wait_for(states.seen.get(), LIMIT)
        assert first == "normal", first
        print("subscribed", flush=True)

        event, fields = await alarm_event(handler, "alarm_raised", alarm_id)
        assert fields["state"] == "unacknowledged", fields
        assert event.SourceNode == device_node.nodeid, event.SourceNode
        ok(f"the alarm_raised event of {alarm_id} arrived: {event.Message.Text!r}")
        _, notified, _ = await asyncio.wait_for(states.seen.get(), LIMIT)
        assert notified == "unacknowledged", notified
        await state_sub.delete()
        ok(f"a subscription to {alarm_id}'s State was told: normal, then unacknowledged")
        await value_becomes(variables["State"], "State unacknowledged", lambda v: v == "unacknowledged")
        assert await variables["Active"].read_value() is True
        assert await variables["Acknowledged"].read_value() is False
        ok(f"{alarm_id}'s variables: State unacknowledged, Active, not Acknowledged")

        comment = "seen by asyncua"
        out = await methods.call_method(method["Acknowledge"], alarm_id, comment)
        assert out == "acknowledged", out
        ok(f"Acknowledge answered {out}")
        event, fields = await alarm_event(handler, "alarm_changed", alarm_id)
        assert fields["changes"] == ["acknowledged"], fields
        assert fields["comment"] == comment, fields
        host, port = client.uaclient.protocol.transport.get_extra_info("sockname")[:2]
        by = f"opcua user operator from {host}:{port} ("
        assert fields["by"].startswith(by), (fields["by"], by)
        ok(f"the alarm_changed event carries changes {fields['changes']}, the comment and by {fields['by']!r}")
        await value_becomes(variables["Acknowledged"], "Acknowledged", lambda v: v is True)
        assert await variables["State"].read_value() == "acknowledged"

        await refused(
            methods.call_method(method["Acknowledge"], alarm_id, "again"),
            ua.StatusCodes.BadConditionBranchAlreadyAcked,
        )
        ok("a second Acknowledge was refused: BadConditionBranchAlreadyAcked")
        await refused(
            methods.call_method(method["Acknowledge"], "no.such:alarm", ""), ua.StatusCodes.BadInvalidArgument
        )
        ok("an unknown alarm was refused: BadInvalidArgument")
        await refused(
            methods.call_method(method["Shelve"], alarm_id, ua.Variant(0.0, ua.VariantType.Double), "no"),
            ua.StatusCodes.BadShelvingTimeOutOfRange,
        )
        ok("a shelving of 0 s was refused: BadShelvingTimeOutOfRange")
        out = await methods.call_method(
            method["Shelve"], alarm_id, ua.Variant(600.0, ua.VariantType.Double), "maintenance"
        )
        event, fields = await alarm_event(handler, "alarm_changed", alarm_id)
        assert fields["changes"] == ["shelved"], fields
        until = await value_becomes(
            variables["ShelvedUntil"], "ShelvedUntil set", lambda v: v is not None and v.year > 2000
        )
        ok(f"Shelve for 600 s answered {out}; ShelvedUntil {until}")
        await methods.call_method(method["Unshelve"], alarm_id, "back")
        event, fields = await alarm_event(handler, "alarm_changed", alarm_id)
        assert fields["changes"] == ["unshelved"], fields
        await refused(
            methods.call_method(method["Unshelve"], alarm_id, "again"), ua.StatusCodes.BadConditionNotShelved
        )
        ok("Unshelve, then a second one refused: BadConditionNotShelved")
        await sub.delete()

        journal = http(addr, f"/api/alarms/journal?alarm={alarm_id}")["entries"]
        acks = [e for e in journal if e["kind"] == "alarm_changed" and e["changes"] == ["acknowledged"]]
        assert len(acks) == 1, journal
        assert acks[0]["comment"] == comment and acks[0]["by"].startswith(by), acks[0]
        kinds = [e["kind"] for e in journal]
        assert kinds.count("alarm_changed") == 3 and "alarm_raised" in kinds, kinds
        ok(f"the alarm journal has the acknowledgement: {acks[0]['message']!r}, by {acks[0]['by']!r}")


async def subtree(node):
    """The node ids of `node` and of everything under it (forward hierarchical references)."""
    found = [node.nodeid]
    for child in await node.get_children():
        found.extend(await subtree(child))
    return found


async def reload(url, removed, added, changed, description, lines):
    async with Client(url, timeout=LIMIT) as client:
        ns, tree = await cell_tree(client)
        assert removed in tree and changed in tree and added not in tree, sorted(tree)
        removed_object = client.get_node(ua.NodeId(removed, ns))
        for folder in ["Production", "Alarms"]:
            assert folder in tree[removed][1], f"{removed} has no {folder} folder: {sorted(tree[removed][1])}"
        gone = await subtree(removed_object)
        point = next(n for name, n in tree[removed][1].items() if name == "air_temperature")
        gateway = await client.nodes.objects.get_child(f"{ns}:Gateway")
        cell_event_type = client.get_node(ua.NodeId("CellbusEventType", ns))
        # The reload's event comes with the lines' line_down events: all of them queued.
        sub, handler = await subscribe_events(client, gateway, cell_event_type, queue=100)
        ok(f"{sorted(tree)} browsed; {removed} has {len(gone)} nodes, its Production and Alarms folders among them")
        print("browsed", flush=True)

        others = []
        try:
            while True:
                event = await asyncio.wait_for(handler.seen.get(), 2 * LIMIT)
                if event.Kind == "config_reloaded":
                    break
                others.append((event.Kind, event.Message.Text))
        except asyncio.TimeoutError:
            raise AssertionError(f"no config_reloaded event from the Gateway object; others: {others}") from None
        fields = json.loads(event.Fields)
        assert fields["removed"] == [removed] and fields["added"] == [added], fields
        ok(f"the config_reloaded event arrived: {event.Message.Text!r}")

        _, tree = await cell_tree(client)
        assert removed not in tree and added in tree and changed in tree, sorted(tree)
        points = [n for name, n in tree[added][1].items() if name not in ["Status", "Error", "Production", "Alarms"]]
        assert points, tree[added]
        for node in points:
            await node.read_data_type()
        value = await tree[added][1]["air_temperature"].read_data_value(raise_on_bad_status=False)
        assert value.StatusCode.is_bad(), value  # its endpoint does not answer
        assert await tree[added][1]["Status"].read_value() in ["connecting", "down", "backed off"]
        ok(f"{added} is found after the reload with its {len(points)} points (air_temperature {value.StatusCode.name})")
        words = (await client.get_node(ua.NodeId(changed, ns)).read_description()).Text
        assert words == description, words
        ok(f"{changed} is described as {words!r}")
        got = await gateway.get_child(f"{ns}:Lines")
        assert await got.read_value() == lines.split(","), await got.read_value()
        ok(f"the Gateway's Lines are {lines}")

        read = await client.uaclient.read_attributes(gone, ua.AttributeIds.BrowseName)
        known = [str(n) for n, v in zip(gone, read) if v.StatusCode.value != ua.StatusCodes.BadNodeIdUnknown]
        assert not known, known
        await refused(point.write_value(ua.Variant(1.0, ua.VariantType.Double)), ua.StatusCodes.BadNodeIdUnknown)
        changes = await client.create_subscription(200, Changes())
        items = await changes.subscribe_data_change([point])
        assert isinstance(items[0], ua.StatusCode) and items[0].value == ua.StatusCodes.BadNodeIdUnknown, items
        ok(f"the {len(gone)} nodes of {removed} are gone: a read, a write and a monitored item are refused BadNodeIdUnknown")
        await changes.delete()
        await sub.delete()


def main():
    mode = sys.argv[1]
    if mode == "reload":
        asyncio.run(asyncio.wait_for(reload(*sys.argv[2:8]), SCRIPT_LIMIT))
        return
    if mode == "alarm":
        asyncio.run(asyncio.wait_for(alarm(*sys.argv[2:6]), SCRIPT_LIMIT))
        return
    if mode == "flood":
        asyncio.run(asyncio.wait_for(flood(*sys.argv[2:5]), SCRIPT_LIMIT))
        return
    if mode == "items":
        asyncio.run(asyncio.wait_for(items(*sys.argv[2:5]), SCRIPT_LIMIT))
        return
    if mode == "down":
        asyncio.run(asyncio.wait_for(down(*sys.argv[2:5]), 240))
        return
    if mode == "anonymous-refused":
        asyncio.run(asyncio.wait_for(anonymous_refused(sys.argv[2]), 60))
        return
    if mode == "read":
        asyncio.run(asyncio.wait_for(read(sys.argv[2], sys.argv[3]), SCRIPT_LIMIT))
    elif mode == "write":
        asyncio.run(asyncio.wait_for(write(*sys.argv[2:6]), SCRIPT_LIMIT))
    else:
        raise SystemExit(f"unknown mode {mode}")


if __name__ == "__main__":
    main()
