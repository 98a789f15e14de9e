"""Boots the USART build of the firmware in QEMU and exchanges protocol v1 frames with it.

(Protocol v2's onboard frames, the design upload and the processor-in-the-loop steps, are
checked by ``firmware/pil.py``.)

QEMU's ``netduinoplus2`` machine is an STM32F405 (the STM32F407 without Ethernet) with USARTs
but no USB OTG model, so the image under test is the ``usart`` build; its first serial port
is USART1. QEMU has no GPIO model either: every input pin reads low, so the H-bridge fault line
(active low) reads "fault" and the firmware must keep the motor disabled and report FAULT; the
encoder timers do not model encoder mode. What is tested is the firmware's protocol handling:
replies, sequence numbers, resynchronisation, RX_ERROR and the disabled driver.

The frames are built and checked with this file's own CRC, independent of the Rust code.

With ``--rip-rt PATH``, the PC's real control loop then runs against a freshly booted image:
the pendulum counter reads 0, which is hanging down, so ``rip-rt run`` must decode the
firmware's measurements and refuse to balance at π rad from upright, sending its stop command.

Usage: python3 firmware/qemu_test.py IMAGE [--rip-rt target/release/rip-rt]
"""

from __future__ import annotations

import os
import re
import select
import struct
import subprocess
import sys
import time
import tty

STATUS_ENABLED, STATUS_WATCHDOG, STATUS_RX_ERROR, STATUS_FAULT = 1, 2, 4, 8


def crc16(data: bytes) -> int:
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def frame(kind: int, seq: int, payload: bytes = b"", version: int = 1) -> bytes:
    body = bytes([version, kind]) + struct.pack("<HB", seq, len(payload)) + payload
    return b"\xa5\x5a" + body + struct.pack("<H", crc16(body))


def request(seq: int) -> bytes:
    return frame(0x03, seq)


def command(seq: int, mv: int, flags: int) -> bytes:
    return frame(0x02, seq, struct.pack("<hB", mv, flags))


class Qemu:
    def __init__(self, image: str) -> None:
        self.proc = subprocess.Popen(
            ["qemu-system-arm", "-M", "netduinoplus2", "-nographic", "-monitor", "none",
             "-serial", "pty", "-kernel", image],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().decode()
        found = re.search(r"(/dev/pts/\d+)", line)
        if not found:
            self.proc.kill()
            raise RuntimeError(f"qemu did not offer a pty: {line!r}")
        self.fd = os.open(found.group(1), os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.fd)
        self.buf = b""
        self.last_seq = -1

    def close(self) -> None:
        os.close(self.fd)
        self.proc.kill()
        self.proc.wait()

    def exchange(self, data: bytes, ack: int, timeout: float = 5.0) -> dict[str, int]:
        """Sends ``data`` and returns the measurement answering the request ``ack``."""
        os.write(self.fd, data)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            ready, _, _ = select.select([self.fd], [], [], 0.1)
            if ready:
                self.buf += os.read(self.fd, 256)
            while (start := self.buf.find(b"\xa5\x5a")) >= 0 and len(self.buf) >= start + 26:
                f, self.buf = self.buf[start:start + 26], self.buf[start + 26:]
                assert f[2:4] == b"\x01\x01" and f[6] == 17, f.hex(" ")
                assert struct.unpack("<H", f[24:26])[0] == crc16(f[2:24]), "CRC"
                (seq,) = struct.unpack("<H", f[4:6])
                self.last_seq = seq
                got, arm, pend, mv, status, t = struct.unpack("<HiihBI", f[7:24])
                if got == ack:
                    return {"seq": seq, "ack": got, "arm": arm, "pendulum": pend,
                            "applied_mv": mv, "status": status, "time_us": t}
        raise TimeoutError(f"no measurement for {ack} within {timeout} s")

    def wait_ready(self, timeout: float = 60.0) -> int:
        """Repeats a sample request until the booted firmware answers one, lets any late
        answers arrive, and returns the sequence number of the device's last measurement."""
        deadline = time.monotonic() + timeout
        for attempt in range(10_000):
            try:
                self.exchange(request(0xA000 + attempt), 0xA000 + attempt, timeout=0.5)
                break
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise
        try:
            self.exchange(b"", -1, timeout=1.0)
        except TimeoutError:
            pass
        return self.last_seq


def main() -> int:
    image = sys.argv[1]
    rip_rt = sys.argv[3] if len(sys.argv) > 3 and sys.argv[2] == "--rip-rt" else None
    qemu = Qemu(image)
    passed = failed = 0

    def check(name: str, ok: bool, detail: object = "") -> None:
        nonlocal passed, failed
        print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")
        if ok:
            passed += 1
        else:
            failed += 1

    try:
        base = qemu.wait_ready()
        m0 = qemu.exchange(request(0x1234), 0x1234)
        check("a sample request is answered with its sequence number echoed",
              m0["ack"] == 0x1234, m0)
        check("the device numbers its measurements one by one", m0["seq"] == base + 1, m0)
        check("the fault line (an unmodelled GPIO, reading low) is reported as FAULT",
              m0["status"] & STATUS_FAULT != 0, m0)
        m1 = qemu.exchange(request(0xFFFF), 0xFFFF)
        check("measurement sequence numbers count up", m1["seq"] == base + 2, m1)
        check("the device clock advances", m1["time_us"] != m0["time_us"], m1)

        m2 = qemu.exchange(command(7, 6000, 1) + request(2), 2)
        check("while the driver reports a fault an enabling command does not enable",
              m2["status"] & STATUS_ENABLED == 0 and m2["applied_mv"] == 0, m2)

        bad = bytearray(request(3))
        bad[5] ^= 0x40
        m3 = qemu.exchange(bytes(bad) + request(4), 4)
        check("after a corrupt frame the next request is answered", m3["seq"] == base + 4, m3)
        check("and the corrupt frame is reported with RX_ERROR",
              m3["status"] & STATUS_RX_ERROR != 0, m3)
        m4 = qemu.exchange(request(5), 5)
        check("RX_ERROR is reported once", m4["status"] & STATUS_RX_ERROR == 0, m4)

        m5 = qemu.exchange(b"\x00\xa5\x13\xa5" + request(6), 6)
        check("garbage before a frame is skipped", m5["seq"] == base + 6, m5)

        # Version 2 is the onboard protocol (its frames are exercised by firmware/pil.py);
        # a version this firmware does not speak is rejected.
        v3 = frame(0x02, 8, struct.pack("<hB", 1000, 1), version=3)
        m6 = qemu.exchange(v3 + request(9), 9)
        check("a CRC-valid frame of version 3 is rejected with RX_ERROR",
              m6["status"] & STATUS_RX_ERROR != 0, m6)
        check("no request went unanswered", m6["seq"] == base + 7, m6)
    finally:
        qemu.close()

    if rip_rt:
        qemu = Qemu(image)
        try:
            qemu.wait_ready()
            port = os.ttyname(qemu.fd)
            run = subprocess.run(
                [rip_rt, "run", "--port", port, "--controller", "lqr", "--duration", "1"],
                capture_output=True, text=True, timeout=60,
            )
        finally:
            qemu.close()
        check("rip-rt run decodes the firmware's measurements: pendulum hanging down",
              run.returncode != 0 and "pendulum at 3.142 rad from upright" in run.stderr,
              run.stderr.strip().splitlines()[:2])
        link = re.search(r"frames=(\d+) crc_errors=(\d+)", run.stderr)
        check("and its link saw frames and no CRC error",
              link is not None and int(link.group(1)) > 0 and link.group(2) == "0",
              link.group(0) if link else run.stderr)
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
