"""Hypothesis fuzzing of the incremental Pelco parser: arbitrary bytes, arbitrary chunking."""

from __future__ import annotations

import itertools

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ptzd.pelco.codec import Frame, FrameParser, Motion, PelcoProtocol, Zoom, encode

SYNC_BYTES = (0xA0, 0xFF)
FUZZ = settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)

motions = st.builds(
    Motion,
    pan=st.integers(-64, 64),
    tilt=st.integers(-63, 63),
    zoom=st.sampled_from(list(Zoom)),
    focus=st.integers(-1, 1),
    iris=st.integers(-1, 1),
)


@st.composite
def valid_frames(draw: st.DrawFn) -> bytes:
    protocol = draw(st.sampled_from(list(PelcoProtocol)))
    high = 256 if protocol == PelcoProtocol.P else 255
    return encode(draw(motions), protocol=protocol, address=draw(st.integers(1, high)))


# Garbage with no sync byte cannot start (or swallow) a frame, so the frames found must be
# exactly the ones embedded.
clean_garbage = st.binary(max_size=40).map(lambda b: bytes(x for x in b if x not in SYNC_BYTES))


def feed_chunked(parser: FrameParser, data: bytes, cuts: list[int]) -> list[Frame]:
    found: list[Frame] = []
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    for start, end in itertools.pairwise(points):
        found += parser.feed(data[start:end])
    return found


def assert_counters_consistent(parser: FrameParser, found: list[Frame], total: int) -> None:
    assert parser.frames == len(found)
    # every byte fed is in a frame, counted as garbage, or still pending
    assert sum(len(f.raw) for f in found) + parser.garbage_bytes + parser.pending == total
    assert parser.bad_checksums >= 0
    assert parser.rejected_frames >= 0
    assert parser.pending < 8


@FUZZ
@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 10_000), max_size=30))
def test_arbitrary_bytes_never_raise_and_chunking_does_not_matter(
    data: bytes, cuts: list[int]
) -> None:
    chunked = FrameParser()
    found = feed_chunked(chunked, data, cuts)
    whole = FrameParser()
    assert whole.feed(data) == found
    assert_counters_consistent(chunked, found, len(data))
    assert (chunked.garbage_bytes, chunked.bad_checksums, chunked.pending) == (
        whole.garbage_bytes,
        whole.bad_checksums,
        whole.pending,
    )


@FUZZ
@given(
    pieces=st.lists(st.tuples(clean_garbage, valid_frames()), max_size=20),
    tail=clean_garbage,
    cuts=st.lists(st.integers(0, 10_000), max_size=40),
)
def test_frames_embedded_in_garbage_are_all_found(
    pieces: list[tuple[bytes, bytes]], tail: bytes, cuts: list[int]
) -> None:
    data = b"".join(g + f for g, f in pieces) + tail
    parser = FrameParser()
    found = feed_chunked(parser, data, cuts)
    assert [f.raw for f in found] == [f for _, f in pieces]
    assert parser.garbage_bytes == sum(len(g) for g, _ in pieces) + len(tail)
    assert parser.bad_checksums == 0
    assert_counters_consistent(parser, found, len(data))


@FUZZ
@given(
    frames=st.lists(valid_frames(), min_size=1, max_size=10),
    flip=st.integers(0, 10_000),
    mask=st.integers(1, 255),
)
def test_one_corrupted_frame_costs_at_most_its_neighbours(
    frames: list[bytes], flip: int, mask: int
) -> None:
    """A flipped bit loses the frame it hits (plus at most the frames it overlaps on resync),
    never the parser; frames wholly after the damage come out again."""
    data = bytearray(b"".join(frames))
    at = flip % len(data)
    data[at] ^= mask
    parser = FrameParser()
    found = parser.feed(bytes(data)) + parser.feed(b"\x00" * 8)  # flush a held prefix
    assert_counters_consistent(parser, found, len(data) + 8)
    # frames that start at least one full frame length after the damage survive
    offsets = [sum(len(f) for f in frames[:i]) for i in range(len(frames))]
    survivors = [f for f, off in zip(frames, offsets, strict=True) if off > at + 8]
    raws = [f.raw for f in found]
    assert raws[len(raws) - len(survivors) :] == survivors
