"""A fake device for the host's link tests: a Transport whose far end is a Python function
that answers each parsed message, as the device would."""

from __future__ import annotations

import time

from graspguide.link import client as gd
from graspguide.link import codec
from graspguide.link import messages as m
from graspguide.link import transport as gt

HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
WRENCH = [0.3, -1.2, -0.8, 0, 0, 0]


class FakeDevice(gt.Transport):
    """A Transport whose far end is ``respond(msg, seq) -> list`` of device messages,
    raw bytes (sent as they are) or None. Frames are parsed as the device would."""

    name = "fake"

    def __init__(self, respond, version: int = m.PROTOCOL_VERSION):
        self.respond = respond
        self.version = version
        self.parser = codec.FrameParser(codec.Accept.HOST_TO_DEVICE)
        self.seq = codec.SequenceCounter()
        self.rx = bytearray()
        self.received = []  # (seq, message) the device got
        self.closed = False

    def frame(self, msg) -> bytes:
        return codec.encode_frame(msg.MSG_ID, self.seq.next(), msg.pack(), self.version)

    def write(self, data: bytes) -> None:
        for event, frame in self.parser.feed(data):
            assert event is codec.ParseEvent.FRAME, event
            msg = codec.message_of(frame)
            self.received.append((frame.seq, msg))
            for out in self.respond(msg, frame.seq) or []:
                self.rx += out if isinstance(out, (bytes, bytearray)) else self.frame(out)

    def read(self, max_bytes: int, timeout: float) -> bytes:
        if not self.rx:
            time.sleep(min(timeout, 0.01))
            return b""
        out = bytes(self.rx[:max_bytes])
        del self.rx[:max_bytes]
        return out

    def close(self) -> None:
        self.closed = True


def telemetry_for(msg: m.Pose, **kw) -> m.Telemetry:
    return m.Telemetry(host_time_us=msg.host_time_us, pwm=(100, 120, 140, 0), **kw)


def good_device(msg, seq):
    """A well-behaved device: ACKs, HELLO_REPLY, TELEMETRY, STATUS."""
    if isinstance(msg, m.Hello):
        return [
            m.HelloReply(
                request_seq=seq,
                protocol_version=m.PROTOCOL_VERSION,
                firmware_version=(0, 1, 0),
                board="fake",
                scalar=4,
                max_contacts=4,
            )
        ]
    if isinstance(msg, m.Pose):
        return [telemetry_for(msg)]
    if isinstance(msg, m.GetStatus):
        return [m.Status(state=m.DeviceState.SCENE_SET)]
    return [m.Ack(request_seq=seq)]


def client_for(respond, timeout=0.2, **kw) -> gd.DeviceClient:
    return gd.DeviceClient(FakeDevice(respond, **kw), timeout=timeout)
