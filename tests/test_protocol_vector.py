"""docs/protocol.md's data-stream test vector is what the code computes: the receiver's and the
sender's MACs, both stream keys and the first sealed record, byte for byte (a foreign host
written from the docs can check itself against it)."""

from __future__ import annotations

import re
from pathlib import Path

import msgpack

from sdrpeer.dataplane.auth import DataAuth, proof_names, proof_parts
from sdrpeer.dataplane.frames import AckOffer, Hello
from sdrpeer.dataplane.seal import Opener, sealed_writer
from sdrpeer.keys.derive import stream_keys

DOC = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"


def vector() -> dict[str, bytes]:
    """The `name = hex` lines of the test vector's code block."""
    text = DOC.read_text()
    block = text.split("**Test vector**", 1)[1].split("```", 2)[1]
    pairs = re.findall(r"^(\w+)\s+=\s+([0-9a-f]+)$", block, re.MULTILINE)
    return {name: bytes.fromhex(value) for name, value in pairs}


def test_the_documented_vector_is_what_the_code_computes() -> None:
    v = vector()
    assert set(v) == {"data_key", "Ns", "Nr", "MACr", "MACs", "key_sr", "key_rs", "frame", "record"}
    assert v["data_key"] == bytes(range(32))
    hello = Hello("c1", "inp", "Pub.out", {}, ack=AckOffer("s1", 1), auth=v["Ns"], enc=True)
    names = proof_names(hello)
    assert names == ("c1", "inp", "Pub.out", "s1", "1")
    parts = proof_parts(hello, sealed=True)  # the MACs also cover the encryption
    assert parts == (*names, "enc")
    auth = DataAuth([v["data_key"]])
    assert auth.receiver_proof(v["Ns"], v["Nr"], parts) == v["MACr"]
    assert auth.check_sender(v["Nr"], v["Ns"], parts, v["MACs"]) == v["data_key"]
    assert stream_keys(v["data_key"], v["Ns"], v["Nr"], names) == (v["key_sr"], v["key_rs"])
    assert msgpack.packb([1, "hi"]) == v["frame"]
    written: list[bytes] = []
    sealed_writer(v["key_sr"], written.append)(v["frame"])
    assert b"".join(written) == v["record"]
    assert b"".join(Opener(v["key_sr"], 1024).open(v["record"])) == v["frame"]
