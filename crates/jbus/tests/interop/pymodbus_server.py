"""A pymodbus RTU server over TCP, for cellbus's interoperability tests.

Usage: python3 pymodbus_server.py

Serves unit 1 with Modbus RTU framing on a TCP socket at 127.0.0.1 on a free port, prints
`listening on tcp://127.0.0.1:PORT` and runs until killed. Its tables:

- coils 0-99 (all off), discrete inputs 0-99 (0 and 2 on), holding registers 0-99
  (register i holds 3 * i), input registers 0-99 (register i holds 1000 + i);
- holding registers 500-502 exist, but any request touching 500 is refused with
  exception 3 (illegal data value), 501 with exception 4 (server device failure) and 502
  with exception 1 (illegal function): pymodbus itself answers every function the client
  sends, so these stand for stricter devices;
- everything else is undefined: exception 2 (illegal data address).

(pymodbus 3.16's simulated devices answer requests for other units with exception 4, not
with silence as a device on a real line would.)
"""

import asyncio

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from serving import serve

UNIT = 1
REFUSALS = {
    500: ExcCodes.ILLEGAL_VALUE,
    501: ExcCodes.DEVICE_FAILURE,
    502: ExcCodes.ILLEGAL_FUNCTION,
}


async def refuse(function_code, start_address, address, count, registers, values):
    """Refuses requests touching the special holding registers."""
    del start_address, registers, values
    if function_code in (3, 6, 16):
        for special, code in REFUSALS.items():
            if address <= special < address + count:
                return code
    return None


async def main():
    device = SimDevice(
        id=UNIT,
        simdata=(
            [SimData(0, count=100, values=False, datatype=DataType.BITS)],
            [SimData(0, values=[True, False, True] + [False] * 97, datatype=DataType.BITS)],
            [
                SimData(0, values=[3 * i for i in range(100)], datatype=DataType.REGISTERS),
                SimData(500, count=3, values=0, datatype=DataType.REGISTERS),
            ],
            [SimData(0, values=[1000 + i for i in range(100)], datatype=DataType.REGISTERS)],
        ),
        action=refuse,
    )
    server = ModbusTcpServer(device, framer=FramerType.RTU, address=("127.0.0.1", 0))
    await serve(server, "tcp")


if __name__ == "__main__":
    asyncio.run(main())
