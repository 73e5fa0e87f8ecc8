"""A pymodbus Modbus TCP server with two units on one port, for cellbus's tests.

Usage: python3 pymodbus_tcp_server.py

Serves Modbus TCP (MBAP framing) at 127.0.0.1 on a free port, prints
`listening on modbus-tcp://127.0.0.1:PORT` and runs until killed. Units 1 and 2 have their
own tables: unit 1's holding register i holds 10 * i, unit 2's 20 * i (0-99); coils 0-99
are all off on both. Holding registers 100-121 of both units hold typed values, encoded
here by Python's struct (not by cellbus): TYPED, from register 100 on.
"""

import asyncio
import struct

from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusTcpServer

from serving import serve

# Typed values from holding register 100 on: float32 in word order CDAB (least significant
# word first), then int32 in ABCD (big-endian), then 12 free registers for typed writes.
TYPED_FLOATS_CDAB = [229.7, -1.5]
TYPED_INTS_ABCD = [-123456, 2000000000, 70000]
TYPED_FREE = 12


def words(fmt, value):
    """The two big-endian 16-bit words of `value` packed by struct as `fmt`."""
    return list(struct.unpack(">HH", struct.pack(fmt, value)))


def typed_registers():
    registers = []
    for value in TYPED_FLOATS_CDAB:
        high, low = words(">f", value)
        registers += [low, high]
    for value in TYPED_INTS_ABCD:
        registers += words(">i", value)
    return registers + [0] * TYPED_FREE


def device(step):
    # ModbusSequentialDataBlock(1, values): register 0 holds the first value.
    return ModbusDeviceContext(
        co=ModbusSequentialDataBlock(1, [False] * 100),
        di=ModbusSequentialDataBlock(1, [False] * 100),
        hr=ModbusSequentialDataBlock(1, [step * i for i in range(100)] + typed_registers()),
        ir=ModbusSequentialDataBlock(1, [0] * 100),
    )


async def main():
    context = ModbusServerContext(devices={1: device(10), 2: device(20)}, single=False)
    server = ModbusTcpServer(context, address=("127.0.0.1", 0))
    await serve(server, "modbus-tcp")


if __name__ == "__main__":
    asyncio.run(main())
