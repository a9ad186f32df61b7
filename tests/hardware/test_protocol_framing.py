"""Protocol 2.0 framing against the e-manual's test vectors."""

from __future__ import annotations

from linkevo.hardware import protocol as p


def test_crc16_check_value():
    assert p.crc16(b"123456789") == 0xFEE8


def test_ping_instruction_matches_manual_vector():
    assert p.build_packet(1, p.PING, b"") == bytes.fromhex("FFFFFD0001030001194E")


def test_ping_status_matches_manual_vector():
    status = p.build_status(1, 0, bytes.fromhex("060426"))
    assert status == bytes.fromhex("FFFFFD000107005500060426655D")


def test_read_and_sync_read_instructions_match_manual_vectors():
    read = p.build_packet(1, p.READ, bytes.fromhex("84000400"))
    assert read == bytes.fromhex("FFFFFD0001070002840004001D15")
    sync = p.build_packet(p.BROADCAST_ID, p.SYNC_READ, bytes.fromhex("840004000102"))
    assert sync == bytes.fromhex("FFFFFD00FE090082840004000102CEFA")


def test_stuffing_inserts_and_removes_fd_after_header_pattern():
    params = b"\x01\xff\xff\xfd\x02"
    packet = p.build_packet(3, p.WRITE, params)
    assert b"\xff\xff\xfd\xfd" in packet
    length = packet[5] | packet[6] << 8
    assert length == len(packet) - 7
    (parsed,) = p.PacketReader().feed(packet)
    assert parsed == p.Packet(3, p.WRITE, params)


def test_reader_skips_junk_and_drops_bad_crc_packets_split_across_reads():
    good = p.build_packet(2, p.READ, bytes.fromhex("84000400"))
    bad = bytearray(p.build_packet(1, p.PING, b""))
    bad[-1] ^= 0x55
    reader = p.PacketReader()
    stream = b"\x00\xff\x13" + bytes(bad) + good
    first = reader.feed(stream[:9])
    rest = reader.feed(stream[9:])
    assert first == []
    assert rest == [p.Packet(2, p.READ, bytes.fromhex("84000400"))]
    assert reader.crc_failures == 1
