"""OptiTrack Motive's NatNet stream as a pose source: ``--source natnet:server=IP,body=NAME``.

Spec keys (every one optional but ``body``; an unknown key is refused with the closest
known one)::

    natnet:server=127.0.0.1,local=0.0.0.0,body=Hand,markers=65537;65538;65539[;65540],
           multicast=239.255.42.99,data_port=1511,command_port=1510,hold=0.2,tol_mm=2,
           stall=0.5,end=10,timeout=5

* ``server``: the Motive PC; ``local``: this PC's interface address (the multicast group
  is joined there; unicast binds it). ``command_port``/``data_port``: Motive's
  Streaming pane (defaults 1510/1511).
* ``multicast``: the group of Motive's Multicast transmission (its default); ``off`` for
  Unicast, where Motive sends frames to the socket that connected.
* ``body``: the rigid body of the hand, by its Streaming ID or its name (resolved from the
  model definitions Motive sends on request).
* ``markers``: 3 or 4 labelled-marker IDs, ``;``-separated, in the order thumb, index,
  middle[, palm]; an ID as NatNet streams it (``MODEL<<16 | INDEX``) or written
  ``MODEL.INDEX``. Contacts are then those markers in the hand frame, ``R^T (p - t)``
  after both are converted to this project's world (metres, z up).
* ``hold``: seconds a pose or contact is kept when the body is not tracked (the frame's
  tracking-valid bit is off, or the body is not in the frame) or a marker is missing or
  occluded; past it the trial is paused: no sample is yielded (so no POSE is sent and the
  device's watchdog turns the motors off) until what was lost is seen again, said once
  on stderr when the pause begins and once when it ends. Times are Motive's frame
  timestamps. This is the rule of :class:`graspguide.sources.marker_contacts.HandTracking`,
  which the LSL source follows too.
* ``tol_mm``: the per-posture re-run tolerance: a sample carries the contacts only when
  one of them moved more than this from the contacts last sent (default 2 mm).
* ``stall``: seconds without a frame that are a *stall* (default 0.5): no sample is
  yielded, so no POSE is sent and the device's watchdog turns the motors off; said once
  on stderr when it begins and once when frames come again, and counted (``stalls`` in
  :meth:`NatNetSource.stats`). A short silence of Motive (a dropped packet run, a busy
  network) is no error.
* ``end``: seconds without a frame after which an iteration ends (default 10; not shorter
  than ``stall``): for `graspguide trial` the trial ends as "the source ended first".
* ``timeout``: seconds to wait for the server's answer, for the first frame after the
  source opened (none by then is a SourceError: Motive does not stream to this PC), and
  for the first tracked frame and every marker's first sight (a rigid body or marker not
  seen by then is a SourceError: its ID is wrong or it is not streamed).

The source can be iterated again (as `graspguide trial` does for each trial): the sockets
stay open until :meth:`NatNetSource.close`; each iteration's ``t_s`` counts from its first
sample, and :meth:`NatNetSource.flush` drops the frames buffered meanwhile.

Samples are ``(t_s, quat_wxyz, contacts_or_None)``, ``t_s`` from Motive's frame timestamp
(seconds since the first frame), converted with the ``optitrack`` tracker convention
(Motive: metres, y up, right-handed, quaternion x, y, z, w) unless ``--tracker`` says
otherwise (a Motive streaming with Up Axis = Z Up: ``--tracker m/z/right/xyzw``).

The NatNet client: ``natnet`` (PyPI, 0.3.0, MIT) was chosen over ``natnetclient`` 0.8.3
(2018: NatNet 2.x layout only, no 3.x residuals or 4.1 data-set sizes, multicast only) and
``natnetsdk`` 4.1.1 (a third party's re-upload of OptiTrack's sample, whose decoders are
name-mangled private methods that print as they go). ``natnet`` decodes a frame of data
into typed records (``DataFrame.read_from_buffer``: rigid bodies with id, position,
quaternion and the tracking-valid bit; labelled markers with id, position, size, params
and residual) for NatNet 2.x to 4.1, and the server's answer (``ServerInfo``) and model
definitions (``DataDescriptions``). Its ``NatNetClient`` receive loop is not used: it
prints its warnings to stdout (where ``graspguide stream`` writes JSON Lines), a malformed
packet ends its receive thread, and its polling mode sends a keep-alive on every poll. So
this module keeps the sockets (the connect request and keep-alive are the 4-byte header
plus a string, as that client sends them) and decodes every packet with ``natnet``'s
decoders; a packet they cannot decode, or one shorter than its header says, is skipped
with a warning on stderr, and a run of them stops the source.

Checked here, with no Motive: packets built by the tests from the published NatNet
3.1/4.1 frame layout (OptiTrack's NatNetClient.py), sent over real UDP on 127.0.0.1 in
unicast by a stand-in server that answers the connect request and the model-definition
request. Not checked against a real Motive: multicast reception, whether Motive sends
unicast frames to the connecting socket (the layout and this behaviour follow the SDK's
sample client), keep-alive needs, packets larger than 64 KiB, and the marker IDs Motive
assigns to labelled fingertip markers. ``natnet`` 0.3.0 does not read NatNet 4.x's
precision timestamp, so its frame-suffix ``param`` is wrong on 4.x; this module uses the
suffix's timestamp only, which comes before it.
"""

from __future__ import annotations

import math
import socket
import struct
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, TextIO

from graspguide.core.suggest import did_you_mean
from graspguide.link.messages import POSE_WATCHDOG_MS
from graspguide.sources.marker_contacts import DEFAULT_HOLD_S, DEFAULT_TOL_MM, HandTracking
from graspguide.sources.poses import (
    TRACKER_PRESETS,
    Sample,
    Source,
    SourceError,
    TrackerConvention,
)

#: Motive's defaults (Streaming pane).
DEFAULT_MULTICAST = "239.255.42.99"
DEFAULT_COMMAND_PORT = 1510
DEFAULT_DATA_PORT = 1511
DEFAULT_TIMEOUT_S = 5.0
DEFAULT_STALL_S = 0.5
DEFAULT_END_S = 10.0
#: This many undecodable packets in a row mean the stream is not NatNet as announced.
MAX_BAD_PACKETS = 20
#: Seconds between unicast keep-alives (the SDK's sample sends one when idle).
KEEPALIVE_S = 1.0

NATNET_OPTIONS: dict[str, str] = {
    "server": "the Motive PC's address",
    "local": "this PC's interface address",
    "body": "the hand's rigid body, Streaming ID or name",
    "markers": "3 or 4 labelled-marker IDs, thumb;index;middle[;palm]",
    "multicast": f"the multicast group ({DEFAULT_MULTICAST}) or off for unicast",
    "data_port": f"Motive's data port ({DEFAULT_DATA_PORT})",
    "command_port": f"Motive's command port ({DEFAULT_COMMAND_PORT})",
    "hold": f"seconds a lost body or marker is kept, then paused ({DEFAULT_HOLD_S})",
    "tol_mm": f"the per-posture re-run tolerance, mm ({DEFAULT_TOL_MM:g})",
    "stall": f"seconds without a frame that are a stall, no POSE sent ({DEFAULT_STALL_S})",
    "end": f"seconds without a frame that end the source ({DEFAULT_END_S:g})",
    "timeout": f"seconds to wait for the server and the first frame ({DEFAULT_TIMEOUT_S})",
}
SPEC = "natnet:server=IP,body=NAME_OR_ID[,markers=ID;ID;ID[;ID]][,multicast=GROUP|off]"


def _natnet():
    try:
        import natnet  # type: ignore[import-untyped]
    except ImportError as e:  # pragma: no cover - setup problem
        raise SourceError(
            f"natnet: the NatNet client is not installed ({e}); install the pinned natnet "
            "(tools/requirements-dev.txt)"
        ) from None
    return natnet


@dataclass(frozen=True)
class NatNetSpec:
    server: str = "127.0.0.1"
    local: str = "0.0.0.0"
    body: str = ""
    markers: tuple[int, ...] = ()
    multicast: str | None = DEFAULT_MULTICAST
    data_port: int = DEFAULT_DATA_PORT
    command_port: int = DEFAULT_COMMAND_PORT
    hold: float = DEFAULT_HOLD_S
    tol_mm: float = DEFAULT_TOL_MM
    stall: float = DEFAULT_STALL_S
    end: float = DEFAULT_END_S
    timeout: float = DEFAULT_TIMEOUT_S


def _address(key: str, value: str) -> str:
    try:
        socket.inet_aton(value)
    except OSError:
        raise SourceError(
            f"natnet: {key} must be an IPv4 address such as 192.168.1.10, got {value!r}"
        ) from None
    return value


def _port(key: str, value: str) -> int:
    try:
        port = int(value)
    except ValueError:
        port = -1
    if not 1 <= port <= 65535:
        raise SourceError(f"natnet: {key} must be a port number 1..65535, got {value!r}")
    return port


def _seconds(key: str, value: str, low: float) -> float:
    try:
        s = float(value)
    except ValueError:
        s = math.nan
    if not (math.isfinite(s) and low < s <= 3600):
        raise SourceError(f"natnet: {key} must be seconds in ({low:g}, 3600], got {value!r}")
    return s


def _millimetres(key: str, value: str) -> float:
    try:
        mm = float(value)
    except ValueError:
        mm = math.nan
    if not (math.isfinite(mm) and 0 <= mm <= 1000):
        raise SourceError(
            f"natnet: {key} must be millimetres in 0..1000, got {value!r} (e.g. "
            f"{key}={DEFAULT_TOL_MM:g})"
        )
    return mm


def marker_id(text: str) -> int:
    """A labelled marker's NatNet ID from ``N`` or ``MODEL.INDEX`` (MODEL << 16 | INDEX)."""
    model, dot, index = text.strip().partition(".")
    try:
        if dot:
            m, i = int(model), int(index)
            if not (0 <= m < 1 << 16 and 0 <= i < 1 << 16):
                raise ValueError
            return m << 16 | i
        n = int(model)
        if not 0 <= n < 1 << 32:
            raise ValueError
        return n
    except ValueError:
        raise SourceError(
            f"natnet: markers: {text!r} is not a labelled-marker ID; write the ID NatNet "
            "streams (e.g. 65537) or MODEL.INDEX (e.g. 1.1), separated by ';'"
        ) from None


def parse_spec(rest: str) -> NatNetSpec:
    """The options of ``natnet:KEY=VALUE,...``; SourceError naming a bad key or value."""
    values: dict[str, object] = {}
    for item in filter(None, (i.strip() for i in rest.split(","))):
        key, eq, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or key not in NATNET_OPTIONS:
            raise SourceError(
                f"natnet: bad option {item!r}{did_you_mean(key, NATNET_OPTIONS)}; options "
                f"are {', '.join(NATNET_OPTIONS)}; written {SPEC}"
            )
        if key in values:
            raise SourceError(f"natnet: {key} is given twice")
        if key in ("server", "local"):
            values[key] = _address(key, value)
        elif key == "multicast":
            values[key] = None if value.lower() == "off" else _address(key, value)
            if values[key] is not None and not value.startswith(("22", "23")):
                raise SourceError(
                    f"natnet: multicast must be a group 224.0.0.0-239.255.255.255 (Motive's "
                    f"default {DEFAULT_MULTICAST}) or off for unicast, got {value!r}"
                )
        elif key in ("data_port", "command_port"):
            values[key] = _port(key, value)
        elif key == "hold":
            values[key] = _seconds(key, value, 0.0)
        elif key in ("timeout", "stall", "end"):
            values[key] = _seconds(key, value, 0.0)
        elif key == "tol_mm":
            values[key] = _millimetres(key, value)
        elif key == "body":
            if not value:
                raise SourceError("natnet: body needs a rigid body's Streaming ID or name")
            values[key] = value
        elif key == "markers":
            ids = tuple(marker_id(m) for m in value.split(";") if m.strip())
            if len(ids) not in (3, 4):
                raise SourceError(
                    f"natnet: markers needs 3 or 4 IDs (thumb;index;middle[;palm]), got "
                    f"{len(ids)}: {value!r}"
                )
            if len(set(ids)) != len(ids):
                raise SourceError(f"natnet: markers names one marker twice: {value!r}")
            values[key] = ids
    if "body" not in values:
        raise SourceError(f"natnet: body is required (the hand's rigid body); written {SPEC}")
    stall = float(values.get("stall", DEFAULT_STALL_S))  # type: ignore[arg-type]
    end = float(values.get("end", DEFAULT_END_S))  # type: ignore[arg-type]
    if end < stall:
        raise SourceError(
            f"natnet: end ({end:g} s) must not be shorter than stall ({stall:g} s); e.g. "
            f"stall={DEFAULT_STALL_S:g},end={DEFAULT_END_S:g}"
        )
    return NatNetSpec(**values)  # type: ignore[arg-type]


def _request(message_id: int, text: str = "") -> bytes:
    body = text.encode("utf-8") + b"\0"
    return struct.pack("<HH", message_id, len(body)) + body


def _warn(text: str) -> None:
    print(f"warning: natnet: {text}", file=sys.stderr, flush=True)


class NatNetSource(Source):
    """Rigid-body poses (and labelled-marker contacts) from Motive's NatNet stream.
    ``notice``: where the one-line notices of a pause go (stderr when None)."""

    name = "natnet"
    simulated = False
    live = True

    def __init__(
        self,
        spec: NatNetSpec,
        convention: TrackerConvention | None = None,
        notice: TextIO | None = None,
    ):
        self.spec = spec
        self.notice = notice
        self.convention = convention or TRACKER_PRESETS["optitrack"]
        self.protocol_version: str | None = None
        self.body_id: int | None = int(spec.body) if spec.body.isdigit() else None
        self.skipped_packets = 0
        self.stalls = 0
        self._bad_run = 0
        # a frame seen since the source opened: silence is a stall, not a setup error
        self._had_frame = False
        self._last_keepalive = -math.inf
        self._nn = _natnet()
        self._command: socket.socket | None = None
        self._data: socket.socket | None = None
        self._version = None
        self._connect()
        self.tracking = HandTracking(
            [f"{i} ({i >> 16}.{i & 0xFFFF})" for i in spec.markers],
            f"{spec.body} (ID {self.body_id})" if spec.body != str(self.body_id) else spec.body,
            self._say,
            spec.hold,
            spec.tol_mm / 1000.0,
        )

    def _say(self, text: str) -> None:
        print(f"natnet: {text}", file=self.notice or sys.stderr, flush=True)

    # -- connection ---------------------------------------------------------------------
    def _connect(self) -> None:
        s = self.spec
        nn = self._nn
        where = f"{s.server}:{s.command_port}"
        try:
            self._command = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
            self._command.bind((s.local if s.multicast is None else "", 0))
            if s.multicast is None:
                self._data = self._command
            else:
                self._data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
                self._data.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self._data.bind(("", s.data_port))
                self._data.setsockopt(
                    socket.IPPROTO_IP,
                    socket.IP_ADD_MEMBERSHIP,
                    socket.inet_aton(s.multicast) + socket.inet_aton(s.local),
                )
            info = self._ask(nn.NatNetClient.NAT_CONNECT, "Ping", nn.NatNetClient.NAT_SERVERINFO)
        except OSError as e:
            self.close()
            raise SourceError(f"natnet: cannot open the NatNet sockets for {where}: {e}") from None
        if info is None:
            self.close()
            raise SourceError(
                f"natnet: no answer from a NatNet server at {where} within {s.timeout:g} s: "
                "check that Motive runs there with Broadcast Frame Data on, and the server, "
                "local and command_port settings"
            )
        server = nn.ServerInfo.read_from_buffer(info, None)
        self._version = server.nat_net_protocol_version
        self.protocol_version = str(self._version)
        self.server_application = server.application_name
        if self.body_id is None:
            self.body_id = self._resolve_body(self.spec.body)

    def _ask(self, request: int, text: str, answer: int):
        """Send a request on the command channel and return the answer's buffer (past its
        header), or None after the timeout. Frames arriving meanwhile are dropped."""
        assert self._command is not None
        s = self.spec
        self._command.sendto(_request(request, text), (s.server, s.command_port))
        deadline = time.monotonic() + s.timeout
        while (left := deadline - time.monotonic()) > 0:
            self._command.settimeout(left)
            try:
                data, _ = self._command.recvfrom(1 << 16)
            except (TimeoutError, ConnectionRefusedError):
                # refused: the host said no program listens on that port
                break
            buf = self._header(data)
            if buf is not None and buf[0] == answer:
                return buf[1]
        return None

    def _header(self, data: bytes):
        """(message id, buffer past the 4-byte header), or None for a short packet."""
        if len(data) < 4:
            self._bad(f"a {len(data)}-byte packet, shorter than the NatNet header")
            return None
        buf = self._nn.PacketBuffer(data)
        message_id = buf.read_uint16()
        size = buf.read_uint16()
        # the 16-bit size cannot count past 64 KiB, so only a shortfall is a truncation
        if len(data) - 4 < size:
            self._bad(f"a truncated packet: {size} bytes announced, {len(data) - 4} received")
            return None
        return message_id, buf

    def _bad(self, what: str) -> None:
        self.skipped_packets += 1
        self._bad_run += 1
        _warn(f"skipped {what} ({self.skipped_packets} skipped so far)")
        if self._bad_run >= MAX_BAD_PACKETS:
            raise SourceError(
                f"natnet: {self._bad_run} undecodable packets in a row from "
                f"{self.spec.server}: the stream is not NatNet {self.protocol_version} as "
                "the server announced; check the server setting and Motive's Streaming pane"
            )

    def _resolve_body(self, name: str) -> int:
        nn = self._nn
        buf = self._ask(nn.NatNetClient.NAT_REQUEST_MODELDEF, "", nn.NatNetClient.NAT_MODELDEF)
        if buf is None:
            raise SourceError(
                f"natnet: the server sent no model definitions within {self.spec.timeout:g} s, "
                f"so the rigid body {name!r} cannot be found; give its Streaming ID instead "
                "(body=N, Motive's Assets pane)"
            )
        try:
            models = nn.DataDescriptions.read_from_buffer(buf, self._version)
        except (struct.error, UnicodeDecodeError, ValueError, nn.NatNetError) as e:
            raise SourceError(
                f"natnet: cannot decode the server's model definitions ({e}); give the "
                "rigid body's Streaming ID instead (body=N)"
            ) from None
        bodies = {rb.name: rb.id_num for rb in models.rigid_bodies if rb.name is not None}
        if name not in bodies:
            known = ", ".join(f"{n!r} (ID {i})" for n, i in bodies.items()) or "none"
            raise SourceError(
                f"natnet: no rigid body named {name!r}{did_you_mean(name, bodies)}; the server "
                f"streams {known}"
            )
        return int(bodies[name])

    def close(self) -> None:
        """Close the sockets (again: nothing); the source cannot be iterated after."""
        for sock in {self._command, self._data}:
            if sock is not None:
                sock.close()
        self._command = self._data = None

    def flush(self) -> int:
        """Drop what the data socket buffered (frames from before now), without blocking:
        the next iteration starts from the frames that arrive after this. Returns how many
        packets were dropped."""
        sock = self._data
        if sock is None:
            return 0
        dropped = 0
        sock.setblocking(False)
        try:
            while True:
                try:
                    sock.recvfrom(1 << 16)
                except (BlockingIOError, ConnectionRefusedError):
                    break
                dropped += 1
        finally:
            sock.setblocking(True)
        return dropped

    # -- frames -------------------------------------------------------------------------
    def frames(self) -> Iterator[object]:
        """Decoded frames of data (``natnet.DataFrame``), skipping undecodable packets.
        No frame for ``stall`` s is a stall (said, counted; the wait goes on), for ``end`` s
        the end of the iteration; no frame at all within ``timeout`` s of the source's
        opening is a SourceError."""
        nn = self._nn
        s = self.spec
        if self._data is None:
            raise SourceError("natnet: the source is closed")
        sock = self._data
        last_packet = time.monotonic()
        stalled = False
        decode_errors = (struct.error, UnicodeDecodeError, ValueError, TypeError, nn.NatNetError)
        while True:
            now = time.monotonic()
            if s.multicast is None and now - self._last_keepalive > KEEPALIVE_S:
                sock.sendto(_request(nn.NatNetClient.NAT_KEEPALIVE), (s.server, s.command_port))
                self._last_keepalive = now
            gap = now - last_packet
            if not self._had_frame:
                if gap >= s.timeout:
                    raise SourceError(
                        f"natnet: no frame from {s.server} for {s.timeout:g} s: check that "
                        "Motive is live (not paused) and streams to this PC"
                    )
                wait = s.timeout - gap
            else:
                if gap > s.stall and not stalled:
                    stalled = True
                    self.stalls += 1
                    self._say(self._stall_text(gap))
                if gap >= s.end:
                    self._say(f"no frame for {s.end:g} s: the source ends")
                    return
                # wake at the stall's and the end's times to say them when they are due
                wait = (s.stall if not stalled else s.end) - gap
            sock.settimeout(max(0.001, min(wait, KEEPALIVE_S)))
            try:
                data, _ = sock.recvfrom(1 << 16)
            except (TimeoutError, ConnectionRefusedError):
                # refused: a keep-alive found the server gone; a stall or the end says so
                continue
            head = self._header(data)
            if head is None or head[0] != nn.NatNetClient.NAT_FRAMEOFDATA:
                continue
            try:
                frame = nn.DataFrame.read_from_buffer(head[1], self._version)
            except decode_errors as e:
                self._bad(f"an undecodable frame of data ({type(e).__name__}: {e})")
                continue
            self._bad_run = 0
            now = time.monotonic()
            if stalled:
                self._say(f"frames again after {now - last_packet:.2f} s: POSEs resume")
                stalled = False
            self._had_frame = True
            last_packet = now
            yield frame

    def _stall_text(self, gap: float) -> str:
        return (
            f"stalled for {gap:.1f} s: no frame from {self.spec.server}, no POSE sent; the "
            f"device's watchdog turns the motors off {POSE_WATCHDOG_MS} ms after the last POSE"
        )

    def __iter__(self) -> Iterator[Sample]:
        # the sockets stay open: the source is iterated again for the next trial
        self.tracking.new_run()
        return self._samples()

    def _samples(self) -> Iterator[Sample]:
        s = self.spec
        conv = self.convention
        tracking = self.tracking
        t0: float | None = None
        start = time.monotonic()
        for frame in self.frames():
            t = float(frame.suffix.timestamp)  # type: ignore[attr-defined]
            rigid_bodies = frame.rigid_bodies  # type: ignore[attr-defined]
            body = next((rb for rb in rigid_bodies if rb.id_num == self.body_id), None)
            pose = None
            if body is not None and body.tracking_valid is not False:
                pose = (conv.quaternion(body.rot), conv.position(body.pos))
            world = None
            if s.markers:
                seen = {
                    m.id_num: m.pos
                    for m in frame.labeled_markers or ()  # type: ignore[attr-defined]
                    # an occluded marker's position is Motive's guess, not a measurement
                    if not (m.param or 0) & 0x01
                }
                world = [conv.position(seen[i]) if i in seen else [math.nan] * 3 for i in s.markers]
            sample = tracking.update(t, pose, world)
            if sample is None:
                if time.monotonic() - start > s.timeout:
                    self._never_seen(body is None)
                continue
            t0 = t if t0 is None else t0
            yield tracking.send(t - t0, sample)

    def _never_seen(self, body_absent: bool) -> None:
        """SourceError when the rigid body or a marker has not been seen once since the
        source started: a wrong ID, or not streamed (not a loss, which pauses)."""
        s = self.spec
        unseen = self.tracking.unseen()
        if not unseen:
            return
        if unseen[0].startswith("rigid body"):
            raise SourceError(
                f"natnet: the rigid body {s.body} (ID {self.body_id}) has not been "
                f"tracked for {s.timeout:g} s: "
                + (
                    "it is not in the stream; check its Streaming ID in Motive's Assets pane"
                    if body_absent
                    else "make it visible to the cameras"
                )
            )
        raise SourceError(
            f"natnet: labelled {unseen[0]} has not been seen for {s.timeout:g} s: check its "
            "ID and that it is labelled in Motive and streamed (Labeled Markers on)"
        )

    def stats(self) -> dict[str, Any]:
        """What the source did: packets skipped, stalls, and :meth:`HandTracking.stats` (frames
        read as samples, POSEs yielded, waiting, rigid-body-lost, held and paused samples,
        pause episodes; with markers the per-posture re-runs)."""
        return {
            "skipped_packets": self.skipped_packets,
            "stalls": self.stalls,
            **self.tracking.stats(),
        }

    def describe(self) -> dict[str, object]:
        s = self.spec
        return {
            "source": self.name,
            "rate_hz": self.rate_hz,
            "server": s.server,
            "transport": "unicast" if s.multicast is None else f"multicast {s.multicast}",
            "natnet_version": self.protocol_version,
            "body": s.body,
            "body_id": self.body_id,
            "markers": list(s.markers),
            "hold_s": s.hold,
            "tol_mm": s.tol_mm,
            "stall_s": s.stall,
            "end_s": s.end,
            "tracker_convention": self.convention.describe(),
        }


def open_natnet_source(rest: str, convention: TrackerConvention | None = None) -> NatNetSource:
    """``--source natnet:...``: see the module's docstring for the keys."""
    return NatNetSource(parse_spec(rest), convention)


__all__ = [
    "NATNET_OPTIONS",
    "NatNetSource",
    "NatNetSpec",
    "marker_id",
    "open_natnet_source",
    "parse_spec",
]
