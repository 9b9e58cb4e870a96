"""The LSM6DSOX driver against a fake I2C holding the datasheet's register values (DS12814:
WHO_AM_I 0x6C, CTRL3_C 0x04 after reset, STATUS_REG bits XLDA/GDA, outputs from 0x22)."""

from graspguide_mp import lsm6dsox as lsm
from graspguide_mp.fake_hal import FakeI2C
from graspguide_mp.frame import STANDARD_GRAVITY_MPS2
from hostless_helpers import close


def _started():
    bus = FakeI2C()
    imu = lsm.Lsm6dsox(bus)
    imu.begin()
    return bus, imu


def test_begin_sets_the_c_boards_ranges():
    bus, _ = _started()
    ctrl1, ctrl2, ctrl3 = bus.configured()
    # ODR 104 Hz = 0100 in bits 7:4 of both; FS_XL 11 = +-8 g; FS_G 11 = +-2000 dps.
    assert ctrl1 >> 4 == 0b0100 and (ctrl1 >> 2) & 0b11 == 0b11
    assert ctrl2 >> 4 == 0b0100 and (ctrl2 >> 2) & 0b11 == 0b11 and not ctrl2 & 0b10
    assert ctrl3 & 0x40 and ctrl3 & 0x04, "block data update and address auto-increment"
    # CTRL3_C first: BDU must hold before the sensors start converting.
    assert bus.writes[0][0] == lsm.REG_CTRL3_C


def test_begin_refuses_another_part_or_none():
    for bus, words in ((FakeI2C(who_am_i=0x69), "WHO_AM_I 0x69"), (FakeI2C(address=0x6B), "0x6a")):
        try:
            lsm.Lsm6dsox(bus).begin()
        except lsm.ImuNotFound as e:
            assert words in str(e), str(e)
        else:
            raise AssertionError("begin() took a bus without an LSM6DSOX")


def test_read_converts_counts():
    bus, imu = _started()
    accel = [0.0, 0.0, 0.0]
    gyro = [0.0, 0.0, 0.0]
    # 1 g is 1/0.244e-3 counts at +-8 g; 70 mdps per count at +-2000 dps.
    one_g = round(1.0 / 0.244e-3)
    bus.set_raw((100, -100, -32768), (0, -one_g, 32767))
    assert imu.read_into(accel, gyro)
    close(accel[1], -one_g * 0.244e-3 * STANDARD_GRAVITY_MPS2, 1e-12, "accel y")
    close(accel[1], -STANDARD_GRAVITY_MPS2, 0.01, "accel y near -1 g")
    close(accel[2], 32767 * 0.244e-3 * STANDARD_GRAVITY_MPS2, 1e-9, "accel z at full scale")
    close(gyro[0], 100 * 0.070 * 3.141592653589793 / 180.0, 1e-15, "gyro x")
    close(gyro[1], -100 * 0.070 * 3.141592653589793 / 180.0, 1e-15, "gyro y")
    close(gyro[2], -32768 * 0.070 * 3.141592653589793 / 180.0, 1e-12, "gyro z, most negative")
    # The part's extreme counts stay near the ranges it reports (the health rule's limits).
    assert accel[2] <= imu.accel_full_scale_mps2() * 1.0001
    assert abs(gyro[2]) > imu.gyro_full_scale_radps(), "the over-range band counts as out"


def test_read_without_new_data_or_bus():
    bus, imu = _started()
    accel = [1.0, 2.0, 3.0]
    gyro = [4.0, 5.0, 6.0]
    bus.set_raw((1, 2, 3), (4, 5, 6), ready=False)
    assert not imu.read_into(accel, gyro)
    assert accel == [1.0, 2.0, 3.0] and gyro == [4.0, 5.0, 6.0]
    bus.set_raw((1, 2, 3), (4, 5, 6))
    bus.regs[lsm.REG_STATUS] = lsm.STATUS_XLDA  # the gyro not yet converted
    assert not imu.read_into(accel, gyro)
    bus.regs[lsm.REG_STATUS] = lsm.STATUS_XLDA | lsm.STATUS_GDA
    bus.fail = True
    assert not imu.read_into(accel, gyro), "a failed transfer is no sample"
