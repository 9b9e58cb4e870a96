"""A small driver of the ST LSM6DSOX (the C++ boards' 6-axis IMU) over any I2C object with
MicroPython's readfrom_mem_into / writeto_mem (machine.I2C on a board, a fake in tests).

Only the registers the host-less mode needs (datasheet DS12814): WHO_AM_I, CTRL1_XL,
CTRL2_G, CTRL3_C, STATUS_REG and the twelve output bytes. Set up as the C++ board does
(lsm6dsox_imu.h): +-8 g, +-2000 dps, 104 Hz. One burst read of gyro and accelerometer
(block data update on, so both belong to the same conversion) into a buffer made once:
a sample allocates nothing. The PyPI package micropython-lsm6dsox (one 0.1.0 release,
2023) reads the two sensors in separate transfers and allocates per read, so it is not
used."""

from graspguide_mp.frame import STANDARD_GRAVITY_MPS2

from micropython import const

ADDRESS = const(0x6A)  # SDO/SA0 low, the Adafruit breakout's default; 0x6B when high
REG_WHO_AM_I = const(0x0F)
WHO_AM_I = const(0x6C)
REG_CTRL1_XL = const(0x10)
REG_CTRL2_G = const(0x11)
REG_CTRL3_C = const(0x12)
REG_STATUS = const(0x1E)
REG_OUTX_L_G = const(0x22)  # gyro x, y, z then accel x, y, z: int16 little-endian

# ODR 104 Hz (0100 in bits 7:4); FS_XL 11 = +-8 g; FS_G 11 = +-2000 dps.
CTRL1_XL_104HZ_8G = const(0x4C)
CTRL2_G_104HZ_2000DPS = const(0x4C)
# BDU (bit 6): output registers update together; IF_INC (bit 2): burst reads advance.
CTRL3_C_BDU_IF_INC = const(0x44)
CTRL3_C_SW_RESET = const(0x01)
STATUS_XLDA = const(0x01)
STATUS_GDA = const(0x02)

# Sensitivities of those ranges: 0.244 mg/LSB and 70 mdps/LSB (datasheet table 2).
ACCEL_MPS2_PER_LSB = 0.244e-3 * STANDARD_GRAVITY_MPS2
GYRO_RADPS_PER_LSB = 70e-3 * 3.141592653589793 / 180.0
ACCEL_FULL_SCALE_MPS2 = 8.0 * STANDARD_GRAVITY_MPS2
# The nominal range; the over-range band up to 2,294 dps counts as out of range (as in C++).
GYRO_FULL_SCALE_RADPS = 2000.0 * 3.141592653589793 / 180.0


class ImuNotFound(OSError):
    pass


def _s16(lo, hi):
    v = lo | (hi << 8)
    return v - 65536 if v & 0x8000 else v


class Lsm6dsox:
    SIX_AXIS = True  # accel is specific force, not a fused gravity

    def __init__(self, i2c, address=ADDRESS):
        self.i2c = i2c
        self.address = address
        self._one = bytearray(1)
        self._out = bytearray(12)

    def _write(self, reg, value):
        self._one[0] = value
        self.i2c.writeto_mem(self.address, reg, self._one)

    def _read(self, reg):
        self.i2c.readfrom_mem_into(self.address, reg, self._one)
        return self._one[0]

    def begin(self):
        """Checks the part and sets it up; ImuNotFound naming the address when another
        part (or none) answers."""
        try:
            who = self._read(REG_WHO_AM_I)
        except OSError as e:
            raise ImuNotFound(
                "no LSM6DSOX answers at I2C address 0x%02x (%s): check SDA/SCL, power and"
                " the SA0 pin (0x6a low, 0x6b high)" % (self.address, e)
            ) from e
        if who != WHO_AM_I:
            raise ImuNotFound(
                "the part at I2C address 0x%02x says WHO_AM_I 0x%02x, not the LSM6DSOX's"
                " 0x%02x: is it another IMU?" % (self.address, who, WHO_AM_I)
            )
        self._write(REG_CTRL3_C, CTRL3_C_BDU_IF_INC)
        self._write(REG_CTRL1_XL, CTRL1_XL_104HZ_8G)
        self._write(REG_CTRL2_G, CTRL2_G_104HZ_2000DPS)

    def accel_full_scale_mps2(self):
        return ACCEL_FULL_SCALE_MPS2

    def gyro_full_scale_radps(self):
        return GYRO_FULL_SCALE_RADPS

    def read_into(self, accel, gyro):
        """True with a new sample in accel (m/s^2) and gyro (rad/s); False when the part
        has none since the last read or the transfer failed (the watchdog turns a long
        silence into a fault)."""
        try:
            ready = self._read(REG_STATUS)
            if ready & (STATUS_XLDA | STATUS_GDA) != STATUS_XLDA | STATUS_GDA:
                return False
            self.i2c.readfrom_mem_into(self.address, REG_OUTX_L_G, self._out)
        except OSError:
            return False
        b = self._out
        g = GYRO_RADPS_PER_LSB
        a = ACCEL_MPS2_PER_LSB
        gyro[0] = _s16(b[0], b[1]) * g
        gyro[1] = _s16(b[2], b[3]) * g
        gyro[2] = _s16(b[4], b[5]) * g
        accel[0] = _s16(b[6], b[7]) * a
        accel[1] = _s16(b[8], b[9]) * a
        accel[2] = _s16(b[10], b[11]) * a
        return True
