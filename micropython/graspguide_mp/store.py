"""The device's non-volatile store (nv_storage.h) and its CRC-32 (storage_crc.h).

A store is a fixed-size byte range whose erased bytes read 0xFF; the plan (plan_file) and
the results log (results_file) share it, at the same offsets as the C++ device. On a board
and on the unix interpreter it is one file (a board's flash file system holds files too),
byte for byte the simulated device's --store file, so the host tools read it unchanged."""

import os

STORE_BYTES = 64 * 1024  # the C++ device's default (GRASPGUIDE_STORE_BYTES)

_CRC_POLY = 0xEDB88320  # reflected 0x04C11DB7: the zlib/PNG CRC-32


def _nibble_table():
    t = []
    for i in range(16):
        c = i
        for _ in range(4):
            c = (c >> 1) ^ _CRC_POLY if c & 1 else c >> 1
        t.append(c)
    return tuple(t)


_NIBBLE = _nibble_table()


def crc32_nibble(data, crc=0):
    """storage_crc.h's CRC-32, two table lookups per byte; crc chains calls as zlib does."""
    c = crc ^ 0xFFFFFFFF
    t = _NIBBLE
    for b in data:
        c ^= b
        c = (c >> 4) ^ t[c & 0x0F]
        c = (c >> 4) ^ t[c & 0x0F]
    return c ^ 0xFFFFFFFF


try:
    # The same polynomial in C where the port has it: a plan's CRC then costs no
    # interpreted loop per byte. Checked against crc32_nibble by the tests.
    from binascii import crc32 as _crc32_c

    if _crc32_c(b"123456789") != 0xCBF43926:
        raise ImportError("binascii.crc32 is another CRC")

    def crc32(data, crc=0):
        return _crc32_c(data, crc) & 0xFFFFFFFF

except ImportError:
    crc32 = crc32_nibble


class StoreError(Exception):
    pass


class MemoryStore:
    """A store in RAM (tests, or a board with no file system to spare)."""

    def __init__(self, size_bytes=STORE_BYTES):
        self.data = bytearray(b"\xff" * size_bytes)

    def size_bytes(self):
        return len(self.data)

    def read(self, offset, n):
        """The n bytes at offset, or None outside the store."""
        if offset < 0 or n < 0 or offset + n > len(self.data):
            return None
        return bytes(self.data[offset : offset + n])

    def write(self, offset, data):
        """True once the bytes are stored; False outside the store."""
        if offset < 0 or offset + len(data) > len(self.data):
            return False
        self.data[offset : offset + len(data)] = data
        return True

    def close(self):
        pass


def _file_size(path):
    try:
        return os.stat(path)[6]
    except OSError:
        return -1


class FileStore:
    """The store as one file of size_bytes: created filled with 0xFF (erased) when
    missing, extended with 0xFF when shorter; a longer file is refused (StoreError) as it
    belongs to another build. Every write is flushed (and synced where the port can)
    before write() returns, so a power cut after it loses none of it."""

    def __init__(self, path, size_bytes=STORE_BYTES):
        if size_bytes < 1:
            raise StoreError("size_bytes must be positive, got %r" % (size_bytes,))
        have = _file_size(path)
        if have > size_bytes:
            raise StoreError(
                "%s is %d bytes, but this device's store is %d bytes: it belongs to another"
                " build; name another file, or delete it to start empty" % (path, have, size_bytes)
            )
        if have < 0:
            with open(path, "wb"):
                pass
            have = 0
        self._f = open(path, "r+b")
        if have < size_bytes:
            self._f.seek(have)
            chunk = b"\xff" * 512
            left = size_bytes - have
            while left > 0:
                n = 512 if left > 512 else left
                self._f.write(chunk[:n])
                left -= n
            self._sync()
        self._size = size_bytes

    def _sync(self):
        self._f.flush()
        sync = getattr(os, "sync", None)
        if sync is not None:
            sync()

    def size_bytes(self):
        return self._size

    def read(self, offset, n):
        if self._f is None or offset < 0 or n < 0 or offset + n > self._size:
            return None
        self._f.seek(offset)
        b = self._f.read(n)
        return b if b is not None and len(b) == n else None

    def write(self, offset, data):
        if self._f is None or offset < 0 or offset + len(data) > self._size:
            return False
        try:
            self._f.seek(offset)
            self._f.write(data)
            self._sync()
        except OSError:
            return False
        return True

    def close(self):
        if self._f is not None:
            self._f.close()
            self._f = None
