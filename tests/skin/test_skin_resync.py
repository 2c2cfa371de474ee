"""Corrupted streams through the Python parser: every intact packet is recovered, none is
invented, and nothing depends on how the stream is cut into chunks."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from skin_helpers import RAW_KEYS, reference_decode

from aptkt.skin import PACKET_TYPES, StreamParser, encode_packet, encode_sensor_packets

OTHER_TYPES = sorted(k for k in PACKET_TYPES if k != "sensor")

raw_row = st.fixed_dictionaries(
    {
        "cell_id": st.integers(0, 0x3FFF),
        "proximity": st.integers(0, 0xFFFF),
        "acc": st.lists(st.integers(-512, 511), min_size=3, max_size=3),
        "temp": st.tuples(st.integers(-128, 127), st.integers(-8192, 8191)),
        "force": st.lists(st.integers(0, 4095), min_size=3, max_size=3),
    }
)


def packet(row: dict) -> bytes:
    return encode_sensor_packets({k: np.array([v]) for k, v in row.items()})


# Damage that cannot glue pieces of other packets into a valid one: garbage has no 0xAA and a
# damaged packet keeps its header. The parser's output must then be exactly the intact packets.
piece = st.one_of(
    st.tuples(st.just("intact"), raw_row),
    st.tuples(st.just("other"), st.sampled_from(OTHER_TYPES), st.binary(min_size=18, max_size=18)),
    st.tuples(st.just("flip"), raw_row, st.integers(1, 18)),  # a payload byte's top bit set
    st.tuples(st.just("drop"), raw_row, st.integers(1, 19), st.integers(1, 19)),  # bytes lost
    st.tuples(st.just("truncate"), raw_row, st.integers(1, 19)),  # the rest never arrives
    st.tuples(
        st.just("garbage"), st.binary(max_size=45).map(lambda b: b.replace(b"\xaa", b"\x2a"))
    ),
)


def build(pieces: list[tuple]) -> tuple[bytes, list[dict], list[str]]:
    stream, intact, others = [], [], []
    for p in pieces:
        kind = p[0]
        if kind == "intact":
            stream.append(packet(p[1]))
            intact.append(p[1])
        elif kind == "other":
            stream.append(encode_packet(p[1], bytes(b & 0x7F for b in p[2])))
            others.append(p[1])
        elif kind == "flip":
            b = bytearray(packet(p[1]))
            b[p[2]] |= 0x80
            stream.append(bytes(b))
        elif kind == "drop":
            b = bytearray(packet(p[1]))
            del b[p[2] : min(20, p[2] + p[3])]
            stream.append(bytes(b))
        elif kind == "truncate":
            stream.append(packet(p[1])[: p[2]])
        else:
            stream.append(p[1])
    return b"".join(stream), intact, others


def parse(stream: bytes, cuts: list[int]) -> tuple[dict[str, np.ndarray], dict]:
    p = StreamParser()
    parts = []
    edges = [0, *sorted(c % (len(stream) + 1) for c in cuts), len(stream)]
    for a, b in zip(edges, edges[1:]):
        parts.append(p.feed(stream[a:b], raw=True))
    out = {k: np.concatenate([x[k] for x in parts]) for k in RAW_KEYS}
    return out, p.stats


def as_rows(out: dict[str, np.ndarray]) -> list[dict]:
    return [
        {
            "cell_id": int(out["cell_id"][i]),
            "proximity": int(out["proximity"][i]),
            "acc": out["acc"][i].tolist(),
            "temp": tuple(out["temp"][i].tolist()),
            "force": out["force"][i].tolist(),
        }
        for i in range(len(out["cell_id"]))
    ]


@settings(max_examples=300, deadline=None)
@given(st.lists(piece, max_size=40), st.lists(st.integers(0, 10**6), max_size=12))
def test_every_intact_packet_and_nothing_else_whatever_the_chunking(pieces, cuts):
    stream, intact, others = build(pieces)
    whole, whole_stats = parse(stream, [])
    assert as_rows(whole) == [dict(r, temp=tuple(r["temp"])) for r in intact]
    assert sum(whole_stats["other_packets"].values()) == len(others)
    for name in set(others):
        assert whole_stats["other_packets"][name] == others.count(name)
    chunked, chunked_stats = parse(stream, cuts)
    for k in RAW_KEYS:
        np.testing.assert_array_equal(chunked[k], whole[k])
    assert chunked_stats == whole_stats
    # Every byte is accounted for: packets, skipped, or held for the next feed.
    packets = whole_stats["packets"] + sum(whole_stats["other_packets"].values())
    assert (
        whole_stats["bytes"]
        == 20 * packets + whole_stats["bytes_skipped"] + whole_stats["pending_bytes"]
    )


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.one_of(piece, st.tuples(st.just("garbage"), st.binary(max_size=45))), max_size=40),
    st.lists(st.integers(0, 10**6), max_size=12),
)
def test_intact_packets_survive_unrestricted_garbage(pieces, cuts):
    # Garbage may now contain 0xAA and whole packet-like byte runs; a packet the parser then
    # finds in the garbage is a genuine valid packet on the wire, but none of the intact
    # packets may be lost.
    stream, intact, _ = build(pieces)
    got = as_rows(parse(stream, cuts)[0])
    it = iter(got)
    for r in intact:
        assert any(g == dict(r, temp=tuple(r["temp"])) for g in it), "intact packet lost"


def test_resume_inside_a_rejected_candidate():
    # A packet truncated after 7 bytes, immediately followed by a complete one: skipping the
    # whole 20-byte candidate would lose the second packet.
    rows = [
        {"cell_id": 1, "proximity": 2, "acc": [3, 4, 5], "temp": (6, 7), "force": [8, 9, 10]},
        {
            "cell_id": 11,
            "proximity": 12,
            "acc": [13, 14, 15],
            "temp": (16, 17),
            "force": [18, 19, 20],
        },
    ]
    stream = packet(rows[0])[:7] + packet(rows[1])
    out, stats = parse(stream, [])
    assert as_rows(out) == [rows[1]]
    assert stats["rejected"]["payload_high_bit"] == 1
    assert stats["bytes_skipped"] == 7
    np.testing.assert_array_equal(reference_decode(stream[7:])["cell_id"], [11])


def test_random_noise_with_embedded_packets_byte_by_byte():
    rng = np.random.default_rng(11)
    rows = [
        {"cell_id": int(c), "proximity": 5, "acc": [1, 2, 3], "temp": (4, 5), "force": [6, 7, 8]}
        for c in rng.integers(1, 8, 200)
    ]
    pieces = []
    for r in rows:
        pieces.append(
            rng.integers(0, 256, rng.integers(0, 30), dtype=np.uint8)
            .tobytes()
            .replace(b"\xaa", b"\x00")
        )
        pieces.append(packet(r))
    stream = b"".join(pieces)
    p = StreamParser()
    out = [p.feed(stream[i : i + 1], raw=True) for i in range(len(stream))]
    cells = np.concatenate([o["cell_id"] for o in out])
    assert cells.tolist() == [r["cell_id"] for r in rows]
