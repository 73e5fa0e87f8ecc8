"""pymodbus as a Modbus TCP client against `cellbus sim modbus --framing tcp`.

Usage: python3 pymodbus_tcp_client.py PORT UNIT

With the default (socket) framer: writes holding registers 10-12 and coils 3-5, reads them
back, and prints one JSON object:

    {"pymodbus": "3.16.1", "registers": [...], "coils": [...], "single": [...]}
"""

import json
import sys

import pymodbus
from pymodbus.client import ModbusTcpClient


def check(response, what):
    if response.isError():
        sys.exit(f"{what} failed: {response}")
    return response


def main():
    port, unit = int(sys.argv[1]), int(sys.argv[2])
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    if not client.connect():
        sys.exit(f"cannot connect to 127.0.0.1:{port}")
    check(client.write_registers(10, [111, 222, 65535], device_id=unit), "function 16")
    check(client.write_register(13, 4242, device_id=unit), "function 6")
    check(client.write_coils(3, [True, False, True], device_id=unit), "function 15")
    check(client.write_coil(6, True, device_id=unit), "function 5")
    registers = check(
        client.read_holding_registers(10, count=4, device_id=unit), "function 3").registers
    coils = check(client.read_coils(3, count=4, device_id=unit), "function 1").bits[:4]
    client.close()
    print(json.dumps({
        "pymodbus": pymodbus.__version__,
        "registers": list(registers),
        "coils": list(coils),
    }))


if __name__ == "__main__":
    main()
