"""MX-28(2.0) control table: contiguous state block, signed conversions, units."""

from __future__ import annotations

import pytest

from linkevo.hardware import control_table as ct


def test_state_block_spans_126_to_146():
    assert ct.block_span(ct.STATE_BLOCK) == (126, 21)


def test_block_span_rejects_a_gap():
    with pytest.raises(ValueError, match="not contiguous"):
        ct.block_span((ct.PRESENT_LOAD, ct.PRESENT_POSITION))


@pytest.mark.parametrize(
    ("value", "size", "raw"),
    [
        (-1, 4, 0xFFFFFFFF),
        (-(2**31), 4, 0x80000000),
        (2**31 - 1, 4, 0x7FFFFFFF),
        (-1000, 2, 0xFC18),
        (-32768, 2, 0x8000),
        (-1, 1, 0xFF),
        (0, 4, 0),
    ],
)
def test_signed_round_trip_at_boundaries(value, size, raw):
    assert ct.to_unsigned(value, size) == raw
    assert ct.to_signed(raw, size) == value


def test_to_unsigned_rejects_values_that_do_not_fit():
    with pytest.raises(ValueError, match="does not fit"):
        ct.to_unsigned(2**32, 4)
    with pytest.raises(ValueError, match="does not fit"):
        ct.to_unsigned(-(2**31) - 1, 4)


def test_decode_reads_signed_items_from_a_block():
    data = bytearray(21)
    data[0:2] = ct.encode(ct.PRESENT_LOAD, -250)
    data[6:10] = ct.encode(ct.PRESENT_POSITION, -5000)
    data[20] = 47
    assert ct.decode(ct.PRESENT_LOAD, data, 126) == -250
    assert ct.decode(ct.PRESENT_POSITION, data, 126) == -5000
    assert ct.decode(ct.PRESENT_TEMPERATURE, data, 126) == 47


def test_units_and_error_names():
    assert ct.units_to_rpm(230) == pytest.approx(52.67)
    assert ct.rpm_to_units(ct.units_to_rpm(100)) == pytest.approx(100)
    assert ct.hardware_error_names(0b100100) == ["overheating", "overload"]
