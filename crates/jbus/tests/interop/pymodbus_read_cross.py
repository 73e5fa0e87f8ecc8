"""pymodbus as an RTU client over TCP against `cellbus sim cross`, for cellbus's tests.

Usage: python3 pymodbus_read_cross.py PORT UNIT

Reads the four defined areas of the CROSS map with function 3, in the order of cellbus's
read plan, then provokes the refusals the manual specifies, and prints one JSON object:

    {"pymodbus": "3.16.1",
     "areas": [[0, [...18 words]], [20, [...4]], [30, [...17]], [70, [...20]]],
     "exceptions": {"<case>": <exception code or null>, ...},
     "silent": {"<case>": true if no answer came, ...}}
"""

import json
import struct
import sys

import pymodbus
from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusIOException
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest

READ_PLAN = [(0x00, 18), (0x14, 4), (0x1E, 17), (0x46, 20)]


class UncheckedRead(ReadHoldingRegistersRequest):
    """Function 3 with any count: pymodbus refuses to send 0 or 126, a CROSS must answer."""

    def encode(self):
        return struct.pack(">HH", self.address, self.count)


def exception_code(response):
    return response.exception_code if response.isError() else None


def main():
    port, unit = int(sys.argv[1]), int(sys.argv[2])
    client = ModbusTcpClient("127.0.0.1", port=port, framer=FramerType.RTU, timeout=1, retries=0)
    if not client.connect():
        sys.exit(f"cannot connect to 127.0.0.1:{port}")
    areas = []
    for address, count in READ_PLAN:
        response = client.read_holding_registers(address, count=count, device_id=unit)
        if response.isError():
            sys.exit(f"reading {count} words at {address:#x} failed: {response}")
        areas.append([address, list(response.registers)])
    exceptions = {
        "function 4": exception_code(client.read_input_registers(0, count=1, device_id=unit)),
        "function 1": exception_code(client.read_coils(0, count=1, device_id=unit)),
        "function 6": exception_code(client.write_register(0, 1, device_id=unit)),
        "function 16": exception_code(client.write_registers(0, [1, 2], device_id=unit)),
        "undefined 0x12": exception_code(
            client.read_holding_registers(0x12, count=2, device_id=unit)),
        "straddling 0x10-0x13": exception_code(
            client.read_holding_registers(0x10, count=4, device_id=unit)),
        "past the map 0x59-0x5A": exception_code(
            client.read_holding_registers(0x59, count=2, device_id=unit)),
        "count 0": exception_code(client.execute(False, UncheckedRead(address=0, count=0, dev_id=unit))),
        "count 126": exception_code(
            client.execute(False, UncheckedRead(address=0, count=126, dev_id=unit))),
    }
    silent = {}
    try:
        client.read_holding_registers(0, count=1, device_id=(unit % 247) + 1)
        silent["another unit"] = False
    except ModbusIOException:
        silent["another unit"] = True
    client.close()
    print(json.dumps({
        "pymodbus": pymodbus.__version__,
        "areas": areas,
        "exceptions": exceptions,
        "silent": silent,
    }))


if __name__ == "__main__":
    main()
