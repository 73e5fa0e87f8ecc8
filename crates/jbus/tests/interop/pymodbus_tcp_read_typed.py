"""pymodbus reads typed values from a Modbus TCP server, decoding them with struct.

Usage: python3 pymodbus_tcp_read_typed.py PORT UNIT ADDRESS COUNT TYPE ORDER

Reads COUNT values of TYPE (float32 or int32) in word ORDER (ABCD: most significant word
first; CDAB: least significant first) from holding register ADDRESS of UNIT, with
pymodbus's client, and decodes them with Python's struct (not with cellbus's decoder).
Prints one JSON object:

    {"registers": [...], "values": [...]}
"""

import json
import struct
import sys

from pymodbus.client import ModbusTcpClient

FORMATS = {"float32": ">f", "int32": ">i"}


def main():
    port, unit, address, count = (int(a) for a in sys.argv[1:5])
    fmt, order = FORMATS[sys.argv[5]], sys.argv[6]
    if order not in ("ABCD", "CDAB"):
        sys.exit(f"order {order}: ABCD or CDAB")
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    if not client.connect():
        sys.exit(f"cannot connect to 127.0.0.1:{port}")
    response = client.read_holding_registers(address, count=2 * count, device_id=unit)
    client.close()
    if response.isError():
        sys.exit(f"function 3 failed: {response}")
    registers = list(response.registers)
    values = []
    for i in range(count):
        first, second = registers[2 * i : 2 * i + 2]
        high, low = (first, second) if order == "ABCD" else (second, first)
        values.append(struct.unpack(fmt, struct.pack(">HH", high, low))[0])
    print(json.dumps({"registers": registers, "values": values}))


if __name__ == "__main__":
    main()
