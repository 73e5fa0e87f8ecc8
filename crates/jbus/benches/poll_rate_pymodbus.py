"""pymodbus polling a paced CROSS simulator, for cellbus's poll-rate bench (poll_rate.rs).

Usage: python3 poll_rate_pymodbus.py PORT UNIT SECONDS ADDRESS:COUNT...

pymodbus's synchronous client, as an RTU client over TCP (framer=FramerType.RTU), reads the
given blocks with function 3 (the bench passes cellbus's read plan of the CROSS: its four
areas) over and over for SECONDS, then prints one line of `name value` pairs:

    pymodbus 3.16.1 cycles N seconds S errors E

where S is the time from the end of the first full cycle to the end of the last one, so
N - 1 cycles fit in S (the connection and the first cycle's warm-up are left out).
"""

import sys
import time

import pymodbus
from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException


def main():
    port, unit, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    plan = [tuple(int(n) for n in block.split(":")) for block in sys.argv[4:]]
    client = ModbusTcpClient("127.0.0.1", port=port, framer=FramerType.RTU, timeout=1, retries=0)
    if not client.connect():
        sys.exit(f"cannot connect to 127.0.0.1:{port}")
    ends = []
    errors = 0
    until = time.monotonic() + seconds
    while time.monotonic() < until:
        ok = True
        for address, count in plan:
            try:
                response = client.read_holding_registers(address, count=count, device_id=unit)
            except ModbusException:
                ok = False
                continue
            if response.isError() or len(response.registers) != count:
                ok = False
        if ok:
            ends.append(time.monotonic())
        else:
            errors += 1
    client.close()
    span = ends[-1] - ends[0] if len(ends) > 1 else 0.0
    print(f"pymodbus {pymodbus.__version__} cycles {len(ends)} seconds {span:.6f} errors {errors}")


if __name__ == "__main__":
    main()
