"""Fakes of hal's interfaces for the unix interpreter: they record what the runner does and
play what a test scripts. No machine import."""

from graspguide_mp.frame import TICKS_MASK
from graspguide_mp.lsm6dsox import (
    REG_CTRL1_XL,
    REG_CTRL2_G,
    REG_CTRL3_C,
    REG_OUTX_L_G,
    REG_STATUS,
    REG_WHO_AM_I,
    WHO_AM_I,
)
from graspguide_mp.store import MemoryStore

EDGE_NONE = 0
EDGE_PRESSED = 1
EDGE_RELEASED = 2


class FakeClock:
    """Ticks a test sets or advances; wraps as the board's clock does."""

    def __init__(self, start_us=0):
        self.t_us = start_us & TICKS_MASK

    def now_us(self):
        return self.t_us

    def now_ms(self):
        return self.t_us // 1000

    def ms_since(self, then_ms):
        return self.t_us // 1000 - then_ms

    def set(self, t_us):
        self.t_us = t_us & TICKS_MASK

    def advance(self, dt_us):
        self.t_us = (self.t_us + dt_us) & TICKS_MASK


class FakeMotors:
    """Keeps the last duty written and how many writes came."""

    def __init__(self):
        self.duty = bytearray(4)
        self.writes = 0

    def write(self, duty):
        for i in range(4):
            self.duty[i] = duty[i]
        self.writes += 1

    def off(self):
        self.write(b"\0\0\0\0")

    def all_off(self):
        return self.duty == b"\0\0\0\0"


class FakeButton:
    """Edges a test pushes, one per poll."""

    def __init__(self):
        self._edges = []
        self._down = False

    def press(self):
        self._edges.append(EDGE_PRESSED)

    def release(self):
        self._edges.append(EDGE_RELEASED)

    def poll(self):
        if not self._edges:
            return EDGE_NONE
        e = self._edges.pop(0)
        self._down = e == EDGE_PRESSED
        return e

    def down(self):
        return self._down


class FakeImu:
    """A 6-axis IMU whose next sample a test sets (None: no new sample)."""

    SIX_AXIS = True

    def __init__(self, accel_fs_mps2=78.4532, gyro_fs_radps=34.906585):
        self._afs = accel_fs_mps2
        self._gfs = gyro_fs_radps
        self.next = None

    def accel_full_scale_mps2(self):
        return self._afs

    def gyro_full_scale_radps(self):
        return self._gfs

    def read_into(self, accel, gyro):
        if self.next is None:
            return False
        a, g = self.next
        self.next = None
        for i in range(3):
            accel[i] = a[i]
            gyro[i] = g[i]
        return True


class FakeI2C:
    """The LSM6DSOX's register file as the datasheet gives it: WHO_AM_I 0x6C, control
    registers 0 after reset, STATUS_REG and the output registers set by the test. fail:
    raise OSError(EIO) on every transfer, as a disconnected bus does."""

    def __init__(self, address=0x6A, who_am_i=WHO_AM_I):
        self.address = address
        self.regs = bytearray(128)
        self.regs[REG_WHO_AM_I] = who_am_i
        self.regs[REG_CTRL3_C] = 0x04  # IF_INC is set at reset
        self.fail = False
        self.writes = []

    def _check(self, addr):
        if self.fail or addr != self.address:
            raise OSError(5)  # EIO: nobody acknowledged

    def readfrom_mem_into(self, addr, reg, buf):
        self._check(addr)
        for i in range(len(buf)):
            buf[i] = self.regs[reg + i]

    def writeto_mem(self, addr, reg, data):
        self._check(addr)
        for i in range(len(data)):
            self.regs[reg + i] = data[i]
            self.writes.append((reg + i, data[i]))

    def set_raw(self, gyro_counts, accel_counts, ready=True):
        """Puts signed 16-bit counts in the output registers (little-endian)."""
        at = REG_OUTX_L_G
        for v in tuple(gyro_counts) + tuple(accel_counts):
            v &= 0xFFFF
            self.regs[at] = v & 0xFF
            self.regs[at + 1] = v >> 8
            at += 2
        self.regs[REG_STATUS] = 0x03 if ready else 0x00

    def configured(self):
        return self.regs[REG_CTRL1_XL], self.regs[REG_CTRL2_G], self.regs[REG_CTRL3_C]


class CutStore(MemoryStore):
    """A store whose writes can be cut: after `budget` more bytes every write stores only
    its prefix and fails, as a power cut during a flash program does. read_fails: every
    read fails."""

    def __init__(self, size_bytes):
        MemoryStore.__init__(self, size_bytes)
        self.budget = -1  # -1: no cut
        self.read_fails = False

    def read(self, offset, n):
        if self.read_fails:
            return None
        return MemoryStore.read(self, offset, n)

    def write(self, offset, data):
        if self.budget < 0:
            return MemoryStore.write(self, offset, data)
        n = len(data) if len(data) < self.budget else self.budget
        if n > 0:
            MemoryStore.write(self, offset, data[:n])
        self.budget -= n
        return n == len(data) and MemoryStore.write(self, offset, data)
