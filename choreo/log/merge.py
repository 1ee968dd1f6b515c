"""`choreo log merge`: the logs of one show's hosts joined into one log every review reads.

A show across hosts is several choreo processes, each with its own robots and its own log, all
on one Ableton Link session. A reviewer wants the show, not the hosts: one log with every robot
on one time line. The merge is two passes over each input, in bounded memory:

- the first reads each log's clock samples (and checks it whole: a damaged, foreign or already
  merged log is one line before anything is written) and lines the logs up: the first input's
  log time is the axis; each other input is shifted by the median, over its clock samples, of
  (the first input's log time at that show beat, interpolated) minus (its own log time at it):
  on the Link clock the show's beat (0 on the bar line the show started on) is the same instant
  on every host, whatever each machine's wall clock says. Over a minute or more, the rate at
  which that offset moves is fitted too (two machines' crystals drift 10-50 ppm apart without
  NTP; a host's seconds drift with its crystal, the session's beats do not). Logs without Link
  samples are lined up by show time the same way (a --loop log by its first pass). With no sample in
  the first's range (no overlap) the runs' recorded show starts (`show_zero_wall_ns`) line them
  up instead, as far as the machines' wall clocks agree: said in a warning.
- the second streams every input's messages in log-time order (a heap merge: one message an
  input in memory) into a new MCAP written beside the output and renamed onto it when whole, so
  a merge that fails leaves nothing half written.

Topics: robots' own topics stay (robot names are unique across a show's hosts; a one-robot
log's `/rcb4/tx` becomes its robot's, and its records are made to name the robot); each host's
shared topics become its own (`/choreo/HOST/log`, `/clock`, `/command`). The reviews time the
show by the first host's clock (`format.clock_topic`): the others are kept, never counted twice.
Metadata: a `choreo` record for the whole (the first host's, with every robot, the hosts and
each one's shift), each input's own records kept under `choreo.host.NAME`, the show attached once.
"""

from __future__ import annotations

import heapq
import json
import math
from bisect import bisect_right
from contextlib import ExitStack
import os
import re
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from statistics import median
from typing import IO, TypeVar

from mcap.writer import CompressionType, Writer

from choreo import __version__
from choreo.clock import RUNNING
from choreo.errors import UsageError
from choreo.log.format import (CHANNELS, CHOREO_TOPICS, CLOCK_TOPIC, METADATA_NAME, PER_HOST, PER_ROBOT,
                               RESULT_METADATA_NAME, SHOW_MEDIA_TYPE, ClockRecord, Info, LogRecord, Result, host_key,
                               host_topic, layout_key, parse, robot_key, robot_message, robot_topic)
from choreo.log.reader import LogReader
from choreo.log.recorder import CHUNK_SIZE, schema_text
from choreo.show.model import LINK
from choreo.userfile import written_whole
from choreo.show.read import MAX_BYTES as SHOW_MAX_BYTES
from choreo.textfit import visible

MAX_INPUTS = 64  # logs one merge takes: each is an open file while the messages stream
SAME_LENGTH_S = 0.5  # hosts' shows this close in length are as long (the first given times the merged one)
UNISON_SPREAD_NS = 20_000_000  # hosts in step agree within this (R1: two hosts a bar apart showed 145-606 ms)
FIT_MIN_SAMPLES = 20  # clock samples before a drift between two machines' clocks is fitted
FIT_MIN_SPAN_NS = 60 * 10**9  # ...over at least this long (less: a shift is one number)
FIT_MAX_RATE = 1e-3  # a drift past 1000 ppm is no crystal's: not fitted (the median shift stands)
MAX_SAMPLES = 20_000  # clock samples a log lines it up by, its first (2.8 hours at two a second)
HOST_METADATA = "choreo.host."  # + host (+ `.result`, ...): each input's own metadata, kept
NAME = re.compile(r"[^\s/,\x00-\x1f\x7f]{1,64}")  # a host or robot name a topic and a list can hold
OUTCOMES = ("failed", "interrupted", "aborted", "done")  # a merged run's outcome: its hosts' worst


@dataclass(frozen=True)
class Alignment:
    """How one input was placed on the first's time line."""

    host: str
    shift_ns: int  # added to its log times
    spread_ns: int  # max - min of the per-sample offsets (0: one sample, or the axis itself)
    samples: int  # clock samples that placed it (0: the show starts placed it)
    by: str  # axis | clock | show start
    rate: float = 0.0  # how much faster its machine's clock ran than the first's (2e-5: 20 ppm), fitted
    ref_ns: int = 0  # the log time (its own) at which the shift is `shift_ns`

    def shift_at(self, log_time: int) -> int:
        """The shift of a message at its own log time (two machines' clocks drift apart)."""
        return self.shift_ns + (round(self.rate * (log_time - self.ref_ns)) if self.rate else 0)

    def describe(self) -> str:
        if self.by == "axis":
            return f"host {self.host}: the time axis"
        drift = f", its clock {-self.rate * 1e6:+.1f} ppm against the first's" if self.rate else ""
        how = (f"spread {self.spread_ns / 1e6:.3f} ms over {self.samples} clock samples{drift}" if self.by == "clock"
               else "by the runs' recorded show starts")
        return f"host {self.host}: shifted {_signed_ms(self.shift_ns)} ({how})"


def _signed_ms(ns: int) -> str:
    """A shift as a reader takes it in: milliseconds to the microsecond, and no `-0.000` (a shift
    of a few ns either way is none)."""
    ms = round(ns / 1e6, 3)
    return f"{ms:+.3f} ms" if ms else "0.000 ms"


@dataclass
class HostLog:
    """One input as the first pass found it."""

    path: Path
    host: str
    robots: tuple[str, ...]  # its robots (a one-robot log: the name its robot is given)
    solo: bool  # a one-robot log: its records name no robot
    metadata: dict[str, dict[str, str]]
    samples: list[tuple[float, int]]  # running clock samples: (show time, log time)
    sources: set[str]  # what kept its show clock (the samples' `source`)
    cut: str | None  # why it ends early (a killed run), if it does
    show: tuple[str, bytes] | None  # its attached show: name, bytes
    beats: list[tuple[float, int, float]] = field(default_factory=list)  # Link samples: (show beat, log time, tempo)


@dataclass
class MergeReport:
    """What `merge_logs` did, for the command to say."""

    output: Path
    hosts: list[HostLog]
    alignments: list[Alignment]
    messages: int = 0
    warnings: list[str] = field(default_factory=list)

    @property
    def robots(self) -> list[str]:
        return [robot for log in self.hosts for robot in log.robots]


def merge_logs(paths: Sequence[str | Path], output: str | Path) -> MergeReport:
    """Merge the hosts' logs `paths` into `output` (UsageError or LogError, one line, if not)."""
    if not os.fspath(output):  # Path('') is '.': said as "-o .", a name the user never wrote
        raise UsageError("-o '': give the path of a new .mcap")
    target = Path(output)
    _check_inputs(paths, target)
    logs = _longest_first([survey(Path(path)) for path in paths])
    _check_hosts(logs)
    report = MergeReport(target, logs, align(logs))
    report.warnings += _warnings(logs, report.alignments)
    _write_atomically(report)
    return report


def _longest_first(logs: list[HostLog]) -> list[HostLog]:
    """The host whose show ran longest first (of those within SAME_LENGTH_S of it, the first
    given; the rest as given): its clock times the merged show and its time is the axis, so the
    merged show lasts as long as its longest host, whatever order the logs were given in (the
    trial: one show read 4.4 s or 9.5 s by the order)."""
    def show_s(log: HostLog) -> float:
        text = log.metadata.get(RESULT_METADATA_NAME, {}).get(Result.SHOW_S, "")
        try:
            value = float(text)
        except ValueError:
            return -math.inf
        return value if math.isfinite(value) else -math.inf
    lengths = [show_s(log) for log in logs]
    # hosts of one show end within a motion of each other: the first given of those, as given
    longest = next(i for i, length in enumerate(lengths) if length >= max(lengths) - SAME_LENGTH_S)
    return [logs[longest], *logs[:longest], *logs[longest + 1:]]


def _check_inputs(paths: Sequence[str | Path], target: Path) -> None:
    if len(paths) < 2:
        raise UsageError("log merge: give the logs of at least two hosts of one show")
    if len(paths) > MAX_INPUTS:
        raise UsageError(f"log merge: {len(paths)} logs given; at most {MAX_INPUTS} hosts' logs make one "
                         "show (merge the logs of one show, not a folder of runs)")
    try:
        info = os.stat(target)
    except OSError:
        info = None
    except ValueError:
        raise UsageError(f"-o {visible(str(target))}: not a file name") from None
    if info is not None and not stat.S_ISREG(info.st_mode):
        raise UsageError(f"-o {visible(str(target))}: not a regular file (give the path of a new .mcap)")
    for path in paths:
        if info is not None and _same_file(Path(path), info):
            raise UsageError(f"-o {visible(str(target))}: is one of the logs merged ({visible(str(path))}); "
                             "write the merged log to a new file")


def _same_file(path: Path, target: os.stat_result) -> bool:
    try:
        mine = os.stat(path)
    except (OSError, ValueError):
        return False
    return (mine.st_dev, mine.st_ino) == (target.st_dev, target.st_ino)


# -- the first pass: what each log is, and its clock ---------------------------------------------


def survey(path: Path) -> HostLog:
    """One input read through once: its host, robots, metadata, clock samples and show."""
    with LogReader(path) as reader:
        if reader.info.hosts:
            raise UsageError(f"log {visible(str(path))}: a merged log already (hosts "
                             f"{visible(', '.join(reader.info.hosts))}); merge the hosts' own logs")
        samples, sources, beats = _clock_samples(reader)
        if reader.cut is not None and reader.cut.damaged:
            raise UsageError(f"log {visible(str(path))}: damaged, not merged: {reader.cut}")
        run_info = reader.run_info
        host = _name(run_info.get(Info.SHOW_HOST) or path.stem, "host", path)
        named = tuple(_name(robot, "robot", path) for robot in reader.robots)
        show = reader.show_attachment()
        shown = (show.name, reader.attachment_data(show)) if show and show.size <= SHOW_MAX_BYTES else None
        return HostLog(path, host, named or (host,), not named, {k: dict(v) for k, v in reader.metadata.items()},
                       samples, sources, str(reader.cut) if reader.cut else None, shown, beats)


def _clock_samples(reader: LogReader) -> tuple[list[tuple[float, int]], set[str], list[tuple[float, int, float]]]:
    """The running show clock's samples, (show time, log time), and on the Link clock (show
    beat, log time); a sample that does not parse or holds no finite time passed over (the
    reviews report such a message)."""
    samples: list[tuple[float, int]] = []
    beats: list[tuple[float, int, float]] = []
    sources: set[str] = set()
    for _, log_time, data in reader.messages((CLOCK_TOPIC,)):
        try:
            sample = parse(CLOCK_TOPIC, data)
        except (KeyError, TypeError, ValueError, AttributeError):
            continue
        if not isinstance(sample, ClockRecord) or sample.state not in (None, RUNNING):
            continue
        if math.isfinite(sample.show_s) and len(samples) < MAX_SAMPLES:
            samples.append((float(sample.show_s), log_time))
            sources.add(sample.source)
            beat, tempo = sample.beat, sample.tempo
            if isinstance(beat, (int, float)) and isinstance(tempo, (int, float)) and math.isfinite(beat + tempo):
                beats.append((float(beat), log_time, float(tempo)))
    return samples, sources, beats


def _name(text: str, what: str, path: Path) -> str:
    if not NAME.fullmatch(text):
        raise UsageError(f"log {visible(str(path))}: its {what} name {visible(text[:70])!r} cannot name a topic "
                         "(1-64 characters, no space, '/' or ','): rename the file")
    return text


def _check_hosts(logs: list[HostLog]) -> None:
    hosts: dict[str, Path] = {}
    robots: dict[str, str] = {}
    for log in logs:
        _check_show(logs[0], log)
        if log.host in hosts:
            raise UsageError(f"log merge: {visible(str(hosts[log.host]))} and {visible(str(log.path))} are both "
                             f"host {visible(log.host)}: give each host's log once")
        hosts[log.host] = log.path
        for robot in log.robots:
            if robot in robots:
                raise UsageError(f"log merge: robot {visible(robot)} is in the logs of hosts {visible(robots[robot])} "
                                 f"and {visible(log.host)}: a show's hosts drive different robots")
            robots[robot] = log.host


def _show_name(log: HostLog) -> str:
    return log.metadata.get(METADATA_NAME, {}).get(Info.SHOW, "")


def _check_show(first: HostLog, log: HostLog) -> None:
    """Hosts of one show ran one show: the runs of two shows have no plan in common, and the
    merged log's one show would label the other's steps with its own (issue 21, item 6)."""
    mine, theirs = _show_name(first), _show_name(log)
    if theirs != mine:
        raise UsageError(f"log merge: {visible(str(first.path))} is a run of show {visible(repr(mine))}, "
                         f"{visible(str(log.path))} of show {visible(repr(theirs))}: merge the logs of one show")


# -- lining the logs up --------------------------------------------------------------------------


def align(logs: list[HostLog]) -> list[Alignment]:
    """Each input's shift onto the first's time line (see the module's docstring): by the show's
    beat where both logs have Link samples (the one thing every host shares: each machine's
    seconds drift against the others'), else by show time."""
    first = logs[0]
    out = [Alignment(first.host, 0, 0, 0, "axis")]
    for log in logs[1:]:
        if first.beats and log.beats:
            pairs = list(_offset_pairs(_increasing_beats(first.beats), _increasing_beats(log.beats)))
        else:
            pairs = list(_offset_pairs(_increasing(first.samples), _increasing(log.samples)))
        if pairs:
            out.append(_fitted(log.host, pairs))
        else:
            out.append(Alignment(log.host, _by_show_start(first, log), 0, 0, "show start"))
    return out


def _fitted(host: str, pairs: list[tuple[int, int]]) -> Alignment:
    """The shift from (log time, offset) pairs: their median, and over a long enough stretch the
    rate at which the offset moves (one machine's crystal against the other's, 10-50 ppm without
    NTP: 144 ms over two hours at 20 ppm), fitted by least squares on the pairs near the median."""
    offsets = sorted(offset for _, offset in pairs)
    shift = round(median(offsets))
    times = [log_time for log_time, _ in pairs]
    ref = round(median(times))
    rate = 0.0
    if len(pairs) >= FIT_MIN_SAMPLES and times[-1] - times[0] >= FIT_MIN_SPAN_NS:
        rate = _slope([(t - ref, o - shift) for t, o in pairs])
        if abs(rate) > FIT_MAX_RATE:
            rate = 0.0
        shift = round(median(o - rate * (t - ref) for t, o in pairs))
    residuals = sorted(o - shift - rate * (t - ref) for t, o in pairs)
    return Alignment(host, shift, round(residuals[-1] - residuals[0]), len(pairs), "clock", rate, ref)


def _slope(points: list[tuple[int, int]]) -> float:
    """Least squares' slope through the points (x, y), x centred already."""
    mean_x = sum(x for x, _ in points) / len(points)
    mean_y = sum(y for _, y in points) / len(points)
    sxx = sum((x - mean_x) ** 2 for x, _ in points)
    return sum((x - mean_x) * (y - mean_y) for x, y in points) / sxx if sxx else 0.0


Sample = TypeVar("Sample", tuple[float, int], tuple[float, int, float])  # (show time or beat, log time, ...)


def _increasing(samples: list[Sample]) -> list[Sample]:
    """The samples whose show time (or beat) goes on from the one before (a loop's rewind left
    out): the axis a show time is interpolated on."""
    kept: list[Sample] = []
    for sample in samples:
        if not kept or (sample[0] > kept[-1][0] and sample[1] > kept[-1][1]):
            kept.append(sample)
    return kept


def offsets_to(axis: list[tuple[float, int]], samples: list[tuple[float, int]]) -> Iterator[int]:
    """(the axis's log time at each sample's show time) - (the sample's log time), in ns, for the
    samples within the axis's span of show time."""
    return (offset for _, offset in _offset_pairs(axis, samples))


def _increasing_beats(samples: list[tuple[float, int, float]]) -> list[tuple[float, int, float]]:
    """The Link samples while the show's beat goes on (a --loop pass's restart left out), less
    the last one before each change of tempo: a host hears of a peer's change some tens of ms
    late, and a sample taken meanwhile reads the beat on the old tempo."""
    kept = _increasing(samples)
    return [one for one, after in zip(kept, [*kept[1:], None], strict=True) if after is None or after[2] == one[2]]


def _offset_pairs(axis: list[Sample], samples: list[Sample]) -> Iterator[tuple[int, int]]:
    """(the sample's log time, its offset): the axis interpolated at each sample's key (a show
    time, or the show's beat on Link) within the axis's span. Samples with a tempo (by the beat)
    pair only between two axis samples at one tempo, the sample at that tempo too: across a
    tempo change the beat is no straight line in time, and each host samples it a few
    milliseconds apart around it."""
    if len(axis) < 2:
        return
    keys = [one[0] for one in axis]
    for sample in samples:
        key, log_time = sample[0], sample[1]
        if not keys[0] <= key <= keys[-1]:
            continue
        at = min(max(bisect_right(keys, key), 1), len(axis) - 1)
        before, after = axis[at - 1], axis[at]
        if before[2:] != after[2:] or after[2:] != sample[2:]:
            continue
        (k0, t0), (k1, t1) = before[:2], after[:2]
        yield log_time, round(t0 + (t1 - t0) * (key - k0) / (k1 - k0)) - log_time


def _by_show_start(first: HostLog, log: HostLog) -> int:
    zeros = [_show_zero(one) for one in (first, log)]
    if zeros[0] is None or zeros[1] is None:
        raise UsageError(f"log merge: cannot line host {visible(log.host)} up with {visible(first.host)}: no clock "
                         "samples at the same show times, and a run without a recorded show start")
    return zeros[0] - zeros[1]


def _show_zero(log: HostLog) -> int | None:
    return whole_ns(log.metadata.get(RESULT_METADATA_NAME, {}).get(Result.SHOW_ZERO_WALL_NS, ""))


def _warnings(logs: list[HostLog], alignments: list[Alignment]) -> list[str]:
    said = []
    for log, alignment in zip(logs, alignments, strict=True):
        if alignment.by == "show start":
            said.append(f"host {log.host}: no clock samples at show times host {logs[0].host}'s log has: lined up by "
                        "the runs' recorded show starts, as far apart as the machines' wall clocks")
        elif alignment.by == "clock" and not (log.sources | logs[0].sources) <= {LINK}:
            said.append(f"host {log.host}: not both on the Link clock "
                        f"({'/'.join(sorted(logs[0].sources | log.sources))}): show time 0 taken as the same instant")
        elif alignment.by == "clock" and alignment.spread_ns > UNISON_SPREAD_NS:
            said.append(f"host {log.host}: its clock samples disagree with host {logs[0].host}'s by up to "
                        f"{alignment.spread_ns / 1e6:.1f} ms: the hosts did not play in step (started on different "
                        "bars, or one lost the session); the merge lines them up on the middle of it")
        if log.cut is not None:
            said.append(f"host {log.host}: its log is unfinished ({log.cut}): merged as far as it goes")
    return said


# -- the second pass: writing the merged log -----------------------------------------------------


def _write_atomically(report: MergeReport) -> None:
    """The merged log, written beside the output and renamed onto it once whole: a merge that
    fails (a log damaged since the first pass, a full disk) leaves no half-written file."""
    with written_whole(report.output, f"-o {visible(str(report.output))}") as file:
        _write(report, file)


def _write(report: MergeReport, file: IO[bytes]) -> None:
    writer = Writer(file, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE)
    writer.start(profile="", library=f"choreo {__version__}")
    channels = _register(writer, report.hosts)
    writer.add_metadata(METADATA_NAME, merged_info(report))
    for log in report.hosts:
        for name, record in log.metadata.items():
            writer.add_metadata(host_metadata_name(log.host, name), record)
    attached: set[bytes] = set()
    for log in report.hosts:
        if log.show is not None and log.show[1] not in attached:  # the show file once
            attached.add(log.show[1])
            start = whole_ns(log.metadata.get(METADATA_NAME, {}).get(Info.START_NS, "")) or 0
            writer.add_attachment(start, start, log.show[0], SHOW_MEDIA_TYPE, log.show[1])
    _stream(writer, report, channels)
    result = merged_result(report.hosts)
    if result is not None:
        writer.add_metadata(RESULT_METADATA_NAME, result)
    writer.finish()


def host_metadata_name(host: str, name: str) -> str:
    """Where an input's metadata record is kept: `choreo` -> `choreo.host.HOST`, `choreo.result`
    -> `choreo.host.HOST.result`, another `NAME` -> `choreo.host.HOST.NAME`."""
    tail = name[len(METADATA_NAME):] if name.startswith(METADATA_NAME + ".") or name == METADATA_NAME else f".{name}"
    return f"{HOST_METADATA}{host}{tail}"


def _register(writer: Writer, logs: list[HostLog]) -> dict[str, int]:
    """Each robot's and each host's topics, each with its JSON schema (Foxglove decodes them)."""
    schemas: dict[str, int] = {}
    channels: dict[str, int] = {}
    for log in logs:
        topics = [(robot_topic(kind, robot), kind) for robot in log.robots for kind in PER_ROBOT]
        for topic, kind in topics + [(host_topic(kind, log.host), kind) for kind in PER_HOST]:
            name, filename = CHANNELS[kind]
            if name not in schemas:
                schemas[name] = writer.register_schema(name=name, encoding="jsonschema", data=schema_text(filename))
            channels[topic] = writer.register_channel(topic=topic, message_encoding="json", schema_id=schemas[name])
    return channels


def _stream(writer: Writer, report: MergeReport, channels: dict[str, int]) -> None:
    """Every input's messages on the one time line, in log-time order: one message an input in
    memory (heapq.merge keeps each input's own order, ties go to the earlier input)."""
    dropped = [0] * len(report.hosts)
    with ExitStack() as stack:
        readers = [stack.enter_context(LogReader(log.path)) for log in report.hosts]
        placed = zip(readers, report.hosts, report.alignments, strict=True)
        streams = [_shifted(reader, log, alignment, dropped, number)
                   for number, (reader, log, alignment) in enumerate(placed)]
        sequence = 0
        for log_time, topic, data in heapq.merge(*streams, key=lambda message: message[0]):
            sequence += 1
            writer.add_message(channels[topic], log_time, data, log_time, sequence % 2 ** 32)
        for reader, log in zip(readers, report.hosts, strict=True):
            if reader.cut is not None and reader.cut.damaged:
                raise UsageError(f"log {visible(str(log.path))}: damaged, not merged: {reader.cut}")
    report.messages = sequence
    for log, count in zip(report.hosts, dropped, strict=True):
        if count:
            report.warnings.append(f"host {log.host}: {count} messages on topics choreo does not write left out")


def _shifted(reader: LogReader, log: HostLog, alignment: Alignment, dropped: list[int],
             number: int) -> Iterator[tuple[int, str, bytes]]:
    """One input's messages as the merged log has them: (log time on the axis, topic, data)."""
    count = 0
    for topic, log_time, data in reader.messages():
        count += 1
        try:
            merged_topic, data = _place(topic, data, log, alignment.shift_at(log_time))
        except (KeyError, TypeError, ValueError) as exc:
            raise reader.not_choreo(topic, count, exc) from None
        if merged_topic is None:
            dropped[number] += 1
            continue
        time = log_time + alignment.shift_at(log_time)
        if not 0 <= time < 2 ** 64:
            raise UsageError(f"log {visible(str(log.path))}: message {count} falls outside MCAP's time range "
                             f"once shifted by {alignment.shift_ns / 1e9:+.3f} s to line up with the others")
        yield time, merged_topic, data


def _place(topic: str, data: bytes, log: HostLog, shift_ns: int = 0) -> tuple[str | None, bytes]:
    """A message's topic in the merged log (None: not choreo's, left out), and its bytes, checked
    as the reviews will read it (a message no review can read is no message to merge)."""
    record = parse(topic, data) if topic in CHOREO_TOPICS else None
    if isinstance(record, LogRecord) and shift_ns:
        data = _shifted_line(record, shift_ns, data)
    if topic in PER_ROBOT:
        robot, data = robot_message(topic, data, log.robots[0] if log.solo else None)
        if robot not in log.robots:
            raise ValueError(f"robot {robot!r:.40} is none of its log's robots")
        return robot_topic(topic, robot), data
    if topic in PER_HOST:
        return host_topic(topic, log.host), data
    return None, data


def _shifted_line(record: LogRecord, shift_ns: int, data: bytes) -> bytes:
    """A log line whose own time (`timestamp`, what Foxglove's log panel shows) is moved as its
    log time is; one whose timestamp holds no time stays as it was written."""
    sec, nsec = record.timestamp.get("sec"), record.timestamp.get("nsec")
    if type(sec) is not int or type(nsec) is not int:
        return data
    moved = LogRecord.at(record.level, record.message, sec * 1_000_000_000 + nsec + shift_ns)
    if moved.timestamp["sec"] < 0:
        return data
    return json.dumps(replace(record, timestamp=moved.timestamp).to_json(), separators=(",", ":")).encode()


# -- the merged log's metadata -------------------------------------------------------------------


def merged_info(report: MergeReport) -> dict[str, str]:
    """The `choreo` record of the whole: the first host's run, every robot, the hosts in order
    (the first's time the axis) and each one's shift onto it."""
    logs = report.hosts
    info = {key: value for key, value in logs[0].metadata.get(METADATA_NAME, {}).items() if key != Info.SHOW_HOST}
    info.update({Info.ROBOTS: ",".join(report.robots), Info.HOSTS: ",".join(log.host for log in logs),
                 Info.UNISON: Info.YES if _unison(logs) else Info.NO})
    for log, alignment in zip(logs, report.alignments, strict=True):
        own = log.metadata.get(METADATA_NAME, {})
        for robot in log.robots:
            for what in (Info.PORT, Info.BAUD, Info.LAYOUT):
                key = (what if what != Info.LAYOUT else layout_key(None)) if log.solo else robot_key(robot, what)
                if key in own:
                    info[robot_key(robot, what)] = own[key]
        info.update({host_key(log.host, Info.SHIFT_NS): str(alignment.shift_ns),
                     host_key(log.host, Info.SPREAD_NS): str(alignment.spread_ns),
                     host_key(log.host, Info.ALIGNED_BY): alignment.by})
    return info


def _unison(logs: list[HostLog]) -> bool:
    """The hosts played one show whose steps their robots share: its plays' starts compare
    across hosts (the summary's unison skew is then host to host too)."""
    infos = [log.metadata.get(METADATA_NAME, {}) for log in logs]
    shows = {info.get(Info.SHOW_SHA256, "") for info in infos}
    said = {info.get(Info.UNISON) for info in infos}
    return len(shows) == 1 and "" not in shows and Info.YES in said and Info.NO not in said


def merged_result(logs: list[HostLog]) -> dict[str, str] | None:
    """The first host's result (its clock times the show) with the hosts' worst outcome and
    their steps summed; None when the first host's run recorded none (it never closed its log)."""
    results = [log.metadata.get(RESULT_METADATA_NAME) for log in logs]
    first = results[0]
    if first is None:
        return None
    merged = dict(first)
    outcomes = [(result or {}).get(Result.OUTCOME, "interrupted") for result in results]
    worst = min(range(len(logs)), key=lambda i: OUTCOMES.index(outcomes[i]) if outcomes[i] in OUTCOMES else 9)
    if outcomes[worst] in OUTCOMES and outcomes[worst] != merged.get(Result.OUTCOME):
        merged[Result.OUTCOME] = outcomes[worst]
        error = (results[worst] or {}).get(Result.ERROR) or "its run recorded no result (its log is unfinished)"
        merged[Result.ERROR] = f"host {logs[worst].host}: {error}"
    for key in (Result.STEPS_RUN, Result.LATE_STEPS):
        counts = [whole_ns((result or {}).get(key, "")) for result in results]
        if all(count is not None for count in counts):
            merged[key] = str(sum(count or 0 for count in counts))
    return merged


def whole_ns(text: str) -> int | None:
    """A whole number from the metadata (hostile text: None for anything else)."""
    return int(text) if text.isascii() and text.isdigit() and len(text) < 20 else None
