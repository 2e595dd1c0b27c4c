"""Tests of the wire format: round trips, keys and rotation, every rejection reason, fuzzing."""

from __future__ import annotations

import base64
import tracemalloc
from pathlib import Path

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sdrpeer.errors import ConfigError, WireError
from sdrpeer.gossip.config import GossipConfig
from sdrpeer.gossip.messages import (
    ALIVE,
    DEAD,
    SUSPECT,
    Ack,
    Alive,
    Dead,
    Digest,
    Event,
    Gossip,
    Nack,
    Packet,
    Ping,
    PingReq,
    Record,
    Suspect,
    Sync,
    Update,
)
from sdrpeer.gossip.replay import MAX_TS_MS
from sdrpeer.gossip.wire import (
    HEADER_SIZE,
    OVERHEAD,
    PROTOCOL_VERSION,
    REASONS,
    REPLAY_WINDOW,
    Codec,
    Keyring,
    ReplayGuard,
    decode_update,
    encode_update,
    encoded_size,
    format_key,
    key_id,
    packet_body,
)

T = 1_700_000_000.0  # wall-clock seconds
T_MS = 1_700_000_000_000
KEY_A = bytes(range(32))
KEY_B = bytes(range(100, 132))
KEY_C = b"c" * 16
UPDATES: tuple[Update, ...] = (
    Alive("r1", ("10.0.0.1", 7946), 3),
    Suspect("r2", 5, "r1"),
    Dead("r3", 7, "r3"),
    Record("r1", 42, b"\x00\xffrecord"),
    Event("r2", 9, "trap", b"payload"),
)
PACKETS: tuple[Packet, ...] = (
    Ping("a", 1, "b"),
    Ping("a", 2, "b", UPDATES),
    Ping("a", 3, "b", tuple(Alive(f"robot-{i:03}", ("10.1.0.1", 7000 + i), i) for i in range(60))),
    PingReq("a", 4, "c", ("192.168.1.3", 0), True, UPDATES[:2]),
    PingReq("a", 5, "c", ("::1", 65535), False),
    Ack("a", 6),
    Ack("a", 7, UPDATES),
    Nack("a", 8, UPDATES[3:]),
    Gossip("a", UPDATES),
    Gossip("a"),
    Sync("a", True, ()),
    Sync(
        "a",
        False,
        (("r1", ("10.0.0.1", 1), 1, ALIVE, 0), ("r2", ("10.0.0.2", 2), 9, DEAD, 4)),
        UPDATES,
    ),
)
INSECURE_HEADER = b"SP" + bytes([PROTOCOL_VERSION]) + bytes(20)


def pair(
    keys_a: list[bytes] | None = None, keys_b: list[bytes] | None = None
) -> tuple[Codec, Codec]:
    """Two codecs, a (sender "a") and b (sender "b"), insecure where keys are None."""
    ring_a = Keyring(keys_a) if keys_a is not None else None
    ring_b = Keyring(keys_b) if keys_b is not None else None
    return Codec("a", ring_a, seq_start=1), Codec("b", ring_b, seq_start=1)


def raw(*objs: object) -> bytes:
    """An unsigned datagram whose body is the msgpack stream of `objs`."""
    return INSECURE_HEADER + b"".join(msgpack.packb(o, use_bin_type=True) for o in objs)


def head(tag: int = 4, sender: object = "a", seq: object = 1, ts: object = T_MS) -> list[object]:
    """A body head; tag 4 (Gossip) needs no more fields."""
    return [tag, sender, seq, ts]


def rejects(codec: Codec, data: bytes, reason: str, now: float = T) -> WireError:
    """`codec` drops `data` for `reason` and counts it; the error raised."""
    before = codec.counters[reason]
    with pytest.raises(WireError) as info:
        codec.decode(data, now)
    assert info.value.reason == reason, info.value
    assert codec.counters[reason] == before + 1
    return info.value


# --- round trips ---------------------------------------------------------------------------


@pytest.mark.parametrize("packet", PACKETS, ids=lambda p: type(p).__name__)
@pytest.mark.parametrize("secure", [True, False])
def test_every_packet_round_trips(packet: Packet, secure: bool) -> None:
    keys = [KEY_A] if secure else None
    a, b = pair(keys, keys)
    data = a.encode(packet, T)
    assert b.decode(data, T + 0.5) == packet
    body = packet_body(packet, 1, T_MS)
    if secure:  # sealed: the body is nowhere in clear, and the envelope is exactly OVERHEAD
        assert len(data) == len(body) + OVERHEAD
        assert body[:8] not in data
    else:
        assert data[HEADER_SIZE:] == body
    assert len(packet_body(packet)) == len(packet_body(packet, int(T * 1e6), T_MS))
    assert a.counters["sent"] == 1
    assert b.counters["accepted"] == 1


def test_decoded_addresses_and_entries_are_tuples() -> None:
    a, b = pair()
    sync = b.decode(a.encode(PACKETS[-1], T), T)
    assert isinstance(sync, Sync)
    assert all(type(e) is tuple and type(e[1]) is tuple for e in sync.entries)
    assert type(sync.entries) is tuple
    assert type(sync.updates) is tuple
    alive = sync.updates[0]
    assert isinstance(alive, Alive)
    assert type(alive.addr) is tuple


@pytest.mark.parametrize("update", UPDATES, ids=lambda u: type(u).__name__)
def test_every_update_round_trips_and_size_is_exact(update: Update) -> None:
    assert decode_update(msgpack.unpackb(msgpack.packb(encode_update(update)))) == update
    assert encoded_size(update) == len(msgpack.packb(encode_update(update), use_bin_type=True))
    bare, full = Gossip("a"), Gossip("a", (update, update))
    assert len(packet_body(full)) == len(packet_body(bare)) + 2 * encoded_size(update)


def test_header_fits_the_configured_overhead() -> None:
    assert HEADER_SIZE == 23
    assert OVERHEAD == 39 <= GossipConfig().packet_overhead


def test_nonces_are_unique_per_datagram_and_per_codec() -> None:
    a = Codec("a", Keyring([KEY_A]), seq_start=1)
    again = Codec("a", Keyring([KEY_A]), seq_start=1)  # the same robot restarted, same seqs
    nonces = [a.encode(Gossip("a"), T)[7:19] for _ in range(100)]
    nonces.append(again.encode(Gossip("a"), T)[7:19])
    assert len(set(nonces)) == 101


def test_seqs_rise_from_seq_start_or_the_first_timestamp() -> None:
    started = Codec("a", None, seq_start=500)
    lazy = Codec("a", None)
    for codec, first in ((started, 500), (lazy, int(T * 1e6))):
        for i in range(3):
            body = packet_body(Gossip("a"), first + i, T_MS)
            assert codec.encode(Gossip("a"), T)[HEADER_SIZE:] == body


def test_a_codec_only_sends_as_its_own_robot() -> None:
    with pytest.raises(ValueError, match="cannot send as"):
        Codec("a", None).encode(Gossip("b"), T)


names = st.text(min_size=1, max_size=20)
uints = st.integers(min_value=0, max_value=2**64 - 1)
addrs = st.tuples(names, st.integers(min_value=0, max_value=65535))
updates = st.one_of(
    st.builds(Alive, names, addrs, uints),
    st.builds(Suspect, names, uints, names),
    st.builds(Dead, names, uints, names),
    st.builds(Record, names, uints, st.binary(max_size=50)),
    st.builds(Event, names, uints, names, st.binary(max_size=50)),
)
update_tuples = st.lists(updates, max_size=8).map(tuple)
entries = st.tuples(names, addrs, uints, st.sampled_from([ALIVE, SUSPECT, DEAD]), uints)
receivers = st.one_of(st.just(""), names)
"""A packet's `to`: no robot (a seed by address) or any robot name."""
packets = st.one_of(
    st.builds(Ping, st.just("a"), uints, names, update_tuples),
    st.builds(PingReq, st.just("a"), uints, names, addrs, st.booleans(), update_tuples, receivers),
    st.builds(Ack, st.just("a"), uints, update_tuples, receivers),
    st.builds(Nack, st.just("a"), uints, update_tuples, receivers),
    st.builds(Gossip, st.just("a"), update_tuples, receivers),
    st.builds(
        Sync,
        st.just("a"),
        st.booleans(),
        st.lists(entries, max_size=5).map(tuple),
        update_tuples,
        receivers,
    ),
)


@settings(max_examples=300, deadline=None)
@given(packets)
def test_any_valid_packet_round_trips(packet: Packet) -> None:
    """Decoded by its receiver (any robot, for a packet to none), it is the packet sent."""
    a = Codec("a", Keyring([KEY_A]), seq_start=1)
    receiver = Codec(packet.to or "robot-9", Keyring([KEY_A]))
    assert receiver.decode(a.encode(packet, T), T) == packet


# --- keys ----------------------------------------------------------------------------------


def test_keyring_from_file_reads_hex_base64_and_comments(tmp_path: Path) -> None:
    path = tmp_path / "cluster.keys"
    path.write_text(
        "# cluster keys, first one signs\n"
        "\n"
        f"{KEY_A.hex()}\n"
        f"   {base64.b64encode(KEY_B).decode()}   # added 2026-01\n"
        f"base64:{base64.b64encode(KEY_C).decode()}\n"
        f"hex:{KEY_C.hex().upper()}\n"  # duplicate: kept once
    )
    ring = Keyring.from_file(path)
    assert ring.signing_key == KEY_A
    assert ring.key_ids == (key_id(KEY_A), key_id(KEY_B), key_id(KEY_C))
    assert len(ring) == 3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (f"{KEY_A.hex()}\nnot a key!\n", ":2: not a hex or base64 key"),
        (f"# c\n\n{KEY_A.hex()[:-1]}\n", ":3: not a hex or base64 key"),
        ("00112233\n", ":1: key has 4 bytes, at least 16"),
        ("# nothing here\n", ": no key in key file"),
    ],
)
def test_bad_key_file_names_file_and_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.keys"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        Keyring.from_file(path)
    assert str(info.value).startswith(f"{path}{message}")


def test_missing_key_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read key file"):
        Keyring.from_file(tmp_path / "absent.keys")


def test_keyring_needs_keys_of_16_bytes() -> None:
    with pytest.raises(ConfigError, match="at least one key"):
        Keyring([])
    with pytest.raises(ConfigError, match="15 bytes"):
        Keyring([KEY_A, b"x" * 15])


def test_generated_keys_are_random_and_formatted_as_hex(tmp_path: Path) -> None:
    k1, k2 = Keyring.generate(), Keyring.generate()
    assert len(k1) == 32
    assert k1 != k2
    path = tmp_path / "k"
    path.write_text(format_key(k1) + "\n" + Keyring.format_key(k2) + "\n")
    assert Keyring.from_file(path).key_ids == (key_id(k1), key_id(k2))


def test_keyring_seals_with_first_opens_with_all_and_hides_keys() -> None:
    ring = Keyring([KEY_A, KEY_B])
    nonce = bytes(range(12))
    sealed = ring.seal(nonce, b"data", b"aad")
    assert b"data" not in sealed
    assert len(sealed) == 4 + 16
    assert ring.open(key_id(KEY_A), nonce, sealed, b"aad") == b"data"
    assert ring.open(key_id(KEY_A), nonce, sealed, b"aae") is None  # header altered
    assert ring.open(key_id(KEY_A), bytes(12), sealed, b"aad") is None  # nonce altered
    assert ring.open(key_id(KEY_B), nonce, sealed, b"aad") is None  # not the sealing key
    tampered = bytes([sealed[0] ^ 1]) + sealed[1:]
    assert ring.open(key_id(KEY_A), nonce, tampered, b"aad") is None
    by_b = Keyring([KEY_B]).seal(nonce, b"data", b"aad")
    assert ring.open(key_id(KEY_B), nonce, by_b, b"aad") == b"data"
    assert KEY_A.hex() not in repr(ring)
    assert key_id(KEY_A).hex() in repr(ring)


def test_key_rotation_without_downtime() -> None:
    def works(sender: Codec, receiver: Codec, now: float) -> bool:
        try:
            receiver.decode(sender.encode(Gossip(sender.sender), now), now)
        except WireError:
            return False
        return True

    # Step 0: everyone has the old key.
    a, b = pair([KEY_A], [KEY_A])
    assert works(a, b, T)
    assert works(b, a, T)
    # Step 1: the new key is added second, robot by robot: old and new rings interoperate.
    a.keyring = Keyring([KEY_A, KEY_B])
    assert works(a, b, T + 1)
    assert works(b, a, T + 1)
    b.keyring = Keyring([KEY_A, KEY_B])
    # Step 2: the new key moves first, robot by robot: it signs, the old one still verifies.
    a.keyring = Keyring([KEY_B, KEY_A])
    assert a.encode(Gossip("a"), T + 2)[3:7] == key_id(KEY_B)
    assert works(a, b, T + 2)
    assert works(b, a, T + 2)
    b.keyring = Keyring([KEY_B, KEY_A])
    # Step 3: the old key is retired, robot by robot.
    a.keyring = Keyring([KEY_B])
    assert works(a, b, T + 3)
    assert works(b, a, T + 3)
    b.keyring = Keyring([KEY_B])
    assert works(a, b, T + 4)
    assert works(b, a, T + 4)
    # A robot that missed the rotation is now locked out.
    stale_robot = Codec("c", Keyring([KEY_A]), seq_start=1)
    rejects(b, stale_robot.encode(Gossip("c"), T + 5), "unknown_key", T + 5)


# --- rejections ----------------------------------------------------------------------------


def test_wrong_key_is_unknown_key() -> None:
    a, b = pair([KEY_A], [KEY_B])
    rejects(b, a.encode(Gossip("a"), T), "unknown_key")


@pytest.mark.parametrize("where", [HEADER_SIZE, -1, 8, 18])
def test_tampered_body_tag_or_nonce_is_unauthenticated(where: int) -> None:
    a, b = pair([KEY_A], [KEY_A])
    data = bytearray(a.encode(Ping("a", 1, "b", UPDATES), T))
    data[where] ^= 0x01
    rejects(b, bytes(data), "unauthenticated")


def test_unsigned_datagram_to_secure_codec_is_unauthenticated() -> None:
    a, b = pair(None, [KEY_A])
    rejects(b, a.encode(Gossip("a"), T), "unauthenticated")


def test_an_insecure_codec_cannot_read_sealed_datagrams() -> None:
    a, b = pair([KEY_A], None)
    rejects(b, a.encode(Gossip("a"), T), "unknown_key")


def test_a_datagram_shorter_than_its_tag_is_malformed() -> None:
    a, b = pair([KEY_A], [KEY_A])
    data = a.encode(Gossip("a"), T)
    rejects(b, data[: HEADER_SIZE + 5], "malformed")


def test_replayed_datagram_is_dropped() -> None:
    a, b = pair([KEY_A], [KEY_A])
    data = a.encode(Ack("a", 3), T)
    assert b.decode(data, T) == Ack("a", 3)
    rejects(b, data, "replayed", T + 1)


# --- binding to the receiver ------------------------------------------------------------------


def robots(*names: str, keys: tuple[bytes, ...] = (KEY_A,)) -> list[Codec]:
    """A codec per robot name, every one holding `keys`."""
    return [Codec(name, Keyring(list(keys)), seq_start=1) for name in names]


def test_a_datagram_replayed_to_another_robot_is_refused_as_wrong_receiver() -> None:
    """Issue 30: the datagrams robot-3 and robot-1 sent robot-2, replayed to robot-1 and to a
    fourth robot at once (well within the freshness window), are refused there, counted as
    wrong_receiver, and none reaches the replay windows of the robots they were replayed to."""
    one, two, three, four = robots("robot-1", "robot-2", "robot-3", "robot-4")
    sent = [
        three.encode(Ping("robot-3", 1, "robot-2", UPDATES), T),
        three.encode(Gossip("robot-3", UPDATES, "robot-2"), T),
        three.encode(Ack("robot-3", 4, (), "robot-2"), T),
        three.encode(Sync("robot-3", True, (), (), "robot-2"), T),
        one.encode(Digest("robot-1", 7, 3, (), "robot-2"), T),  # back to its own sender
        one.encode(PingReq("robot-1", 5, "robot-3", ("h", 1), True, (), "robot-2"), T),
    ]
    for data in sent:
        assert two.decode(data, T).to == "robot-2"
    for other in (one, four):
        for data in sent:
            rejects(other, data, "wrong_receiver", T + 1)
        assert other.counters["wrong_receiver"] == len(sent)
        assert other.counters["accepted"] == 0
        assert len(other.guard) == 0


def test_receiver_ids_differ_per_robot_and_per_key_and_are_never_none() -> None:
    """Keyed: another cluster key gives other ids (no one without the key can compute them);
    stable for one key; never the all-zero id of a datagram to no robot."""
    ring = Keyring([KEY_A, KEY_B])
    names = [f"robot-{i}" for i in range(500)]
    ids_a = [ring.receiver_ids(n)[0] for n in names]
    ids_b = [ring.receiver_ids(n, key_id(KEY_B))[0] for n in names]
    assert len(set(ids_a)) == len(names)
    assert not set(ids_a) & set(ids_b)
    assert ids_a == [Keyring([KEY_A]).receiver_ids(n)[0] for n in names]
    assert bytes(4) not in ids_a + ids_b
    assert ring.receiver_ids("robot-1", bytes(4)) == ()  # no key with that id


def test_a_receiver_id_pasted_from_another_robots_traffic_does_not_open() -> None:
    """Someone who watched robot-1's traffic knows its receiver id (it is in clear): put into
    a datagram sealed for robot-2, it passes the id check and fails the tag (the associated
    data holds the receiver's own name); made unbound (zeros), it fails the tag too."""
    one, two, three = robots("robot-1", "robot-2", "robot-3")
    to_one = three.encode(Gossip("robot-3", (), "robot-1"), T)
    to_two = bytearray(three.encode(Gossip("robot-3", UPDATES, "robot-2"), T))
    rid = slice(HEADER_SIZE - 4, HEADER_SIZE)
    to_two[rid] = to_one[rid]
    rejects(one, bytes(to_two), "unauthenticated")
    to_two[rid] = bytes(4)
    rejects(one, bytes(to_two), "unauthenticated")
    rejects(two, bytes(to_two), "unauthenticated")


def test_a_datagram_to_no_robot_opens_anywhere_once() -> None:
    """A join by address (the seed's name unknown): any robot holding the key takes it, once."""
    one, two, three = robots("robot-1", "robot-2", "robot-3")
    join = three.encode(Sync("robot-3", True, (("robot-3", ("h", 1), 0, ALIVE, 1),)), T)
    for robot in (one, two):
        packet = robot.decode(join, T)
        assert isinstance(packet, Sync)
        assert packet.to == ""
        assert packet.reply
        rejects(robot, join, "replayed", T + 1)


def test_binding_holds_across_a_key_rotation() -> None:
    """The sender seals with the new key, which the receiver holds second: its receiver id
    under that key is found, and a replay elsewhere is still refused."""
    (sender,) = robots("robot-3", keys=(KEY_B, KEY_A))
    one, two = robots("robot-1", "robot-2", keys=(KEY_A, KEY_B))
    data = sender.encode(Gossip("robot-3", UPDATES, "robot-2"), T)
    assert data[3:7] == key_id(KEY_B)
    assert two.decode(data, T) == Gossip("robot-3", UPDATES, "robot-2")
    rejects(one, data, "wrong_receiver")


def test_what_was_sent_to_an_earlier_life_is_stale_in_the_new_one() -> None:
    """robot-2 restarts (its replay windows are gone): a datagram addressed to its previous
    life, replayed well within the freshness window, is refused as stale, not taken again;
    what is sent after the new life began is taken."""
    two, three = robots("robot-2", "robot-3")
    before = three.encode(Gossip("robot-3", UPDATES, "robot-2"), T)
    assert two.decode(before, T) == Gossip("robot-3", UPDATES, "robot-2")
    (again,) = robots("robot-2")
    again.clock.offset_ms = two.clock.offset_ms  # the agent keeps it across restarts
    again.begin_life(T + 5)
    error = rejects(again, before, "stale", T + 6)
    assert error.sender_behind  # its seq is new here: answered once (the shell's nudge)
    after = three.encode(Gossip("robot-3", UPDATES, "robot-2"), T + 5.5)
    assert again.decode(after, T + 6) == Gossip("robot-3", UPDATES, "robot-2")
    rejects(again, before, "stale", T + 7)


def test_a_stale_replay_is_not_taken_for_a_sender_behind() -> None:
    """Only a stale datagram newer than all its sender sent us says its clock is behind (the
    shell answers it); a stale replay of recorded traffic, once newer traffic came, does not."""
    a, b = pair([KEY_A], [KEY_A])
    recorded = a.encode(Gossip("a", (), "b"), T)
    assert b.decode(a.encode(Gossip("a", (), "b"), T + 5), T + 5).sender == "a"
    error = rejects(b, recorded, "stale", T + 36)
    assert not error.sender_behind
    assert error.sender == "a"
    behind = rejects(b, a.encode(Gossip("a", (), "b"), T + 6), "stale", T + 40)
    assert behind.sender_behind
    assert behind.sender == "a"


@pytest.mark.parametrize("delay", [30.001, 3600.0])
def test_datagram_outside_the_freshness_window_is_stale(delay: float) -> None:
    a, b = pair([KEY_A], [KEY_A])
    error = rejects(b, a.encode(Gossip("a"), T), "stale", T + delay)
    assert error.sender_behind  # authenticated: its sender is only behind
    assert b.decode(a.encode(Gossip("a"), T), T + 30.0) == Gossip("a")


def test_a_clock_ahead_moves_the_cluster_time_on_and_replays_stay_stale() -> None:
    """b's clock is an hour behind a's: b takes a's datagram (a replay can only be older)
    and from then on stamps and judges with a's time."""
    a, b = pair([KEY_A], [KEY_A])
    old = a.encode(Gossip("a"), T - 60)  # recorded a minute before
    assert b.decode(a.encode(Gossip("a"), T), T - 3600) == Gossip("a")
    assert b.clock.offset_ms == 3600_000
    assert b.counters["clock_advanced"] == 1
    assert a.decode(b.encode(Gossip("b"), T - 3600 + 1), T + 1) == Gossip("b")  # fresh for a
    rejects(b, old, "stale", T - 3600 + 1)  # the replay is older than the cluster time
    c = Codec("c", Keyring([KEY_A]), seq_start=1)
    rejects(c, old, "stale", T)  # and for anyone whose clock is right


def test_unauthenticated_stale_datagrams_do_not_say_the_sender_is_behind() -> None:
    a, b = pair(None, None)
    assert not rejects(b, a.encode(Gossip("a"), T), "stale", T + 60).sender_behind


def test_without_keys_nothing_moves_the_time_and_the_future_is_refused() -> None:
    a, b = pair(None, None)
    rejects(b, a.encode(Gossip("a"), T + 60), "stale", T)  # anyone could have dated it
    assert b.decode(a.encode(Gossip("a"), T + 20), T) == Gossip("a")  # within the window
    assert b.clock.offset_ms == 0


def test_an_absurd_timestamp_is_refused_and_the_codec_keeps_working() -> None:
    a, b = pair([KEY_A], [KEY_A])
    rejects(b, a.encode(Gossip("a"), MAX_TS_MS / 1000 + 1), "stale", T)
    assert b.clock.offset_ms == 0
    far = a.encode(Gossip("a"), MAX_TS_MS / 1000 - 1)  # the latest time still accepted
    assert b.decode(far, T) == Gossip("a")
    assert len(b.encode(Gossip("b"), T)) > 0  # stamping at the far time still encodes
    rejects(b, a.encode(Gossip("a"), T), "stale", T)  # a key holder set the time (security.md)


def test_freshness_window_is_configurable() -> None:
    a = Codec("a", None, seq_start=1)
    b = Codec("b", None, freshness_s=2.0)
    rejects(b, a.encode(Gossip("a"), T), "stale", T + 2.5)


def test_wrong_version_is_dropped_before_the_mac() -> None:
    a, b = pair([KEY_A], [KEY_A])
    data = bytearray(a.encode(Gossip("a"), T))
    data[2] = PROTOCOL_VERSION + 1
    rejects(b, bytes(data), "version")


def test_oversized_datagrams_are_refused_both_ways() -> None:
    small = Codec("a", Keyring([KEY_A]), max_datagram=200, seq_start=1)
    big = Ping("a", 1, "b", UPDATES * 10)
    with pytest.raises(WireError) as info:
        small.encode(big, T)
    assert info.value.reason == "oversized"
    assert small.counters["send_oversized"] == 1
    assert small.counters["sent"] == 0
    data = Codec("a", Keyring([KEY_A]), seq_start=1).encode(big, T)
    rejects(Codec("b", Keyring([KEY_A]), max_datagram=200), data, "oversized")


@pytest.mark.parametrize(
    ("data", "detail"),
    [
        (b"", "short"),
        (b"SP\x01", "header only partly"),
        (b"XX" + INSECURE_HEADER[2:] + msgpack.packb(head()), "bad magic"),
        (INSECURE_HEADER, "no body"),
        (raw([99, "a", 1, T_MS]), "unknown packet tag"),
        (raw(head(sender="")), "empty sender"),
        (raw(head(sender="x" * 256)), "sender too long"),
        (raw(head(sender=b"a")), "bytes sender"),
        (raw(head(seq=-1)), "negative seq"),
        (raw(head(seq=True)), "bool seq"),
        (raw(head(ts=1.5)), "float timestamp"),
        (raw(head()[:3]), "head too short"),
        (raw({"tag": 4}), "map head"),
        (raw([0, "a", 1, T_MS, 1]), "ping without target"),
        (raw([1, "a", 1, T_MS, 1, "c", ["h", 70000], True]), "port out of range"),
        (raw([1, "a", 1, T_MS, 1, "c", ["h", 1, 2], True]), "addr of 3"),
        (raw([1, "a", 1, T_MS, 1, "c", ["h", 1], 1]), "int want_nack"),
        (raw([5, "a", 1, T_MS, True, 2], ["r", ["h", 1], 1, 0, 0]), "missing sync entry"),
        (raw([5, "a", 1, T_MS, True, 1], ["r", ["h", 1], 1, 7, 0]), "bad member state"),
        (raw([5, "a", 1, T_MS, True, 1], ["r", ("h", 1), 1, 0]), "short sync entry"),
        (raw(head(), [0, "r", ["h", 1], -3]), "negative incarnation"),
        (raw(head(), [3, "r", 1, "not bytes"]), "str payload"),
        (raw(head(), [2, "r", 1]), "dead without source"),
        (raw(head(), "not an update"), "update not an array"),
        (raw(head(), []), "empty update"),
        (raw(head()) + b"\x93\x01", "truncated update"),
        (raw(head()) + b"\xc1", "reserved msgpack byte"),
        (raw(head(), [4, "r", 1, "k", b"p"]) + b"\xa2\xff\xfe", "invalid utf-8"),
        (raw(head(), [0] + [1] * 40), "array over the field cap"),
    ],
    ids=lambda x: x if isinstance(x, str) else "",
)
def test_malformed_datagrams(data: bytes, detail: str) -> None:
    rejects(Codec("b", None), data, "malformed")


def test_hostile_nesting_allocates_little() -> None:
    codec = Codec("b", None)
    nested = INSECURE_HEADER + msgpack.packb(head()) + b"\xdc\x00\x20" * 20_000
    tracemalloc.start()
    try:
        rejects(codec, nested, "malformed")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000


def test_unknown_update_is_skipped_and_counted() -> None:
    codec = Codec("b", None)
    future = [17, "from", b"the future", [1, 2], {"k": msgpack.ExtType(1, b"x")}]
    data = raw(head(), [0, "r", ["h", 1], 2], future, [3, "r", 1, b""])
    got = codec.decode(data, T)
    assert got == Gossip("a", (Alive("r", ("h", 1), 2), Record("r", 1, b"")))
    assert codec.counters["unknown_update"] == 1
    assert codec.counters["accepted"] == 1
    assert decode_update([17, "x"]) is None


def test_trailing_fields_from_newer_peers_are_ignored() -> None:
    codec = Codec("b", None)
    data = raw([2, "a", 1, T_MS, 5, "new"], [1, "r", 2, "s", "new field"])
    assert codec.decode(data, T) == Ack("a", 5, (Suspect("r", 2, "s"),))


def test_codec_recovers_after_a_bad_body() -> None:
    a, b = pair(None, None)
    rejects(b, raw(head()) + b"\x93\x01", "malformed")  # leaves half an array in the unpacker
    assert b.decode(a.encode(Gossip("a", UPDATES), T), T) == Gossip("a", UPDATES)


def test_callers_can_count_their_own_rejections() -> None:
    codec = Codec("b", None)
    error = codec.reject("malformed", "from the shell")
    assert error.reason == "malformed"
    assert codec.counters["malformed"] == 1


# --- replay window -------------------------------------------------------------------------


def test_replay_window_edges() -> None:
    guard = ReplayGuard()
    top = 10_000
    assert guard.check("a", top, T_MS, T_MS) is None
    assert guard.check("a", top - REPLAY_WINDOW, T_MS, T_MS) == "replayed"  # too old
    assert guard.check("a", top - REPLAY_WINDOW + 1, T_MS, T_MS) is None  # oldest remembered
    assert guard.check("a", top - REPLAY_WINDOW + 1, T_MS, T_MS) == "replayed"
    assert guard.check("a", top - 5, T_MS, T_MS) is None  # out of order, once
    assert guard.check("a", top - 5, T_MS, T_MS) == "replayed"
    assert guard.check("a", top, T_MS, T_MS) == "replayed"
    assert guard.check("a", top + 3, T_MS, T_MS) is None  # window slides by 3
    assert guard.check("a", top - 5, T_MS, T_MS) == "replayed"  # still remembered
    assert guard.check("a", top + 1, T_MS, T_MS) is None  # skipped over, then arrives
    assert guard.check("a", top + 3 + 5000, T_MS, T_MS) is None  # a jump clears the window
    assert guard.check("a", top + 3 + 5000 - REPLAY_WINDOW + 1, T_MS, T_MS) is None
    assert guard.check("b", top - 5, T_MS, T_MS) is None  # seqs are per sender


def test_stale_datagram_is_not_recorded() -> None:
    guard = ReplayGuard(freshness_s=30.0)
    assert guard.check("a", 7, T_MS - 30_001, T_MS) == "stale"
    assert len(guard) == 0
    assert guard.check("a", 7, T_MS - 30_000, T_MS) is None


def test_tracked_senders_are_bounded_least_recently_seen_evicted() -> None:
    guard = ReplayGuard(max_senders=100)
    for i in range(100):
        assert guard.check(f"r{i}", 1, T_MS, T_MS) is None
    assert guard.check("r0", 2, T_MS, T_MS) is None  # r0 seen again: r1 is now the oldest
    for i in range(100, 1000):
        assert guard.check(f"r{i}", 1, T_MS, T_MS) is None
        assert len(guard) <= 100
    assert len(guard) == 100
    guard = ReplayGuard(max_senders=2)
    guard.check("r0", 1, T_MS, T_MS)
    guard.check("r1", 1, T_MS, T_MS)
    guard.check("r0", 2, T_MS, T_MS)
    guard.check("r2", 1, T_MS, T_MS)  # evicts r1, the least recently seen
    assert guard.check("r0", 2, T_MS, T_MS) == "replayed"
    assert guard.check("r1", 1, T_MS, T_MS) is None  # forgotten, so accepted again


def test_codec_bounds_tracked_senders() -> None:
    codec = Codec("z", None, max_senders=10)
    for i in range(50):
        codec.decode(Codec(f"r{i}", None, seq_start=1).encode(Gossip(f"r{i}"), T), T)
    assert len(codec.guard) == 10
    assert codec.counters["accepted"] == 50


# --- fuzzing: nothing but WireError ever escapes decode ------------------------------------


def decode_or_wire_error(codec: Codec, data: bytes) -> None:
    """Decode `data`; any rejection must be a WireError with a known, counted reason."""
    total = sum(codec.counters.values())
    try:
        codec.decode(data, T)
    except WireError as e:
        reason = e.reason
    else:
        return
    assert reason in REASONS
    assert sum(codec.counters.values()) == total + 1


FUZZ = settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(st.binary(max_size=300))
def test_random_bytes_only_raise_wire_error(data: bytes) -> None:
    decode_or_wire_error(Codec("b", Keyring([KEY_A])), data)
    decode_or_wire_error(Codec("b", None), data)
    decode_or_wire_error(Codec("b", None), INSECURE_HEADER + data)


VALID = Codec("a", None, seq_start=1).encode(PACKETS[-1], T)
VALID_SIGNED = Codec("a", Keyring([KEY_A]), seq_start=1).encode(PACKETS[1], T)


def test_truncations_only_raise_wire_error() -> None:
    """Every cut of a valid datagram, plain and signed: all of them, fewer than a fuzz tries."""
    for cut in range(len(VALID) + 1):
        decode_or_wire_error(Codec("b", None), VALID[:cut])
    for cut in range(len(VALID_SIGNED) + 1):
        decode_or_wire_error(Codec("b", Keyring([KEY_A])), VALID_SIGNED[:cut])


@FUZZ
@given(st.data())
def test_mutated_bodies_only_raise_wire_error(data: st.DataObject) -> None:
    body = bytearray(VALID)
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(HEADER_SIZE, len(body) - 1))
        body[at] = data.draw(st.integers(0, 255))
    decode_or_wire_error(Codec("b", None), bytes(body))


msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats()
    | st.text(max_size=8)
    | st.binary(max_size=8),
    lambda inner: st.lists(inner, max_size=6) | st.dictionaries(st.text(max_size=4), inner),
    max_leaves=6,
)


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.integers(0, 6),
    st.lists(msgpack_values, max_size=6),
    st.lists(st.lists(msgpack_values, max_size=5), max_size=4),
)
def test_wrong_typed_fields_only_raise_wire_error(
    tag: int, fields: list[object], items: list[list[object]]
) -> None:
    datagram = raw([tag, "a", 1, T_MS, *fields], *([i % 6, *rest] for i, rest in enumerate(items)))
    decode_or_wire_error(Codec("b", None), datagram)


def test_decode_accepts_any_bytes_like() -> None:
    a, b = pair([KEY_A], [KEY_A])
    data = a.encode(Gossip("a", UPDATES), T)
    assert b.decode(bytearray(data), T) == Gossip("a", UPDATES)
    assert b.decode(memoryview(a.encode(Gossip("a"), T)), T) == Gossip("a")
