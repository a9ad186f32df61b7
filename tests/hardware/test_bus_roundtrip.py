"""The real dynamixel-sdk against the bus emulator on a pty: every instruction round-trips."""

from __future__ import annotations

import time

import pytest
from dynamixel_sdk import COMM_SUCCESS, GroupBulkRead, GroupBulkWrite, PacketHandler, PortHandler

from linkevo.hardware import control_table as ct
from linkevo.hardware import protocol as p
from linkevo.hardware.bus import DxlBus
from linkevo.hardware.errors import CommError, DeviceError, MotorNotResponding, PortError

IDS = [1, 2, 3]


@pytest.fixture
def emu(emulator):
    return emulator(IDS)


@pytest.fixture
def bus(emu):
    with DxlBus(emu.port, 1_000_000, retries=0) as bus:
        yield bus


def test_ping_returns_the_mx28_model(bus):
    assert [bus.ping(i) for i in IDS] == [ct.MX28_MODEL_NUMBER] * 3


def test_broadcast_ping_lists_every_motor(emu):
    port = PortHandler(emu.port)
    assert port.openPort()
    try:
        found, result = PacketHandler(2.0).broadcastPing(port)
    finally:
        port.closePort()
    assert result == COMM_SUCCESS
    assert sorted(found) == IDS
    assert all(model == ct.MX28_MODEL_NUMBER for model, _ in found.values())


def test_read_returns_defaults_and_write_changes_them(bus, emu):
    assert bus.read(2, ct.OPERATING_MODE) == ct.POSITION_MODE
    assert bus.read(2, ct.VELOCITY_LIMIT) == 230
    bus.write(2, ct.OPERATING_MODE, ct.VELOCITY_MODE)
    assert bus.read(2, ct.OPERATING_MODE) == ct.VELOCITY_MODE
    assert emu.snapshot(2).operating_mode == ct.VELOCITY_MODE
    assert emu.snapshot(1).operating_mode == ct.POSITION_MODE


def test_sync_write_and_sync_read_in_one_packet_each(bus, emu):
    for i in IDS:
        bus.write(i, ct.OPERATING_MODE, ct.VELOCITY_MODE)
        bus.write(i, ct.TORQUE_ENABLE, 1)
    before = len(emu.packets())
    bus.sync_write(ct.GOAL_VELOCITY, {1: 100, 2: -100, 3: 0})
    statuses = bus.sync_read(ct.STATE_BLOCK, IDS)
    sent = emu.packets()[before:]
    assert [q.instruction for q in sent] == [p.SYNC_WRITE, p.SYNC_READ]
    velocities = {i: s.values["present_velocity"] for i, s in statuses.items()}
    assert velocities == {1: 100, 2: -100, 3: 0}
    assert not any(s.alert for s in statuses.values())


def test_bulk_read_and_bulk_write_through_the_sdk(emu):
    port, packets = PortHandler(emu.port), PacketHandler(2.0)
    assert port.openPort()
    try:
        writer = GroupBulkWrite(port, packets)
        writer.addParam(1, ct.PROFILE_VELOCITY.address, 4, list(ct.encode(ct.PROFILE_VELOCITY, 77)))
        writer.addParam(3, ct.RETURN_DELAY_TIME.address, 1, [5])
        assert writer.txPacket() == COMM_SUCCESS
        reader = GroupBulkRead(port, packets)
        reader.addParam(1, ct.PROFILE_VELOCITY.address, 4)
        reader.addParam(3, ct.RETURN_DELAY_TIME.address, 1)
        assert reader.txRxPacket() == COMM_SUCCESS
        assert reader.getData(1, ct.PROFILE_VELOCITY.address, 4) == 77
        assert reader.getData(3, ct.RETURN_DELAY_TIME.address, 1) == 5
    finally:
        port.closePort()


def test_reboot_clears_a_hardware_error_and_drops_torque(bus, emu):
    bus.write(1, ct.TORQUE_ENABLE, 1)
    emu.set_hardware_error(1, 1 << ct.OVERLOAD_BIT)
    status = bus.sync_read(ct.STATE_BLOCK, [1, 2])
    assert status[1].alert and not status[2].alert
    assert bus.read(1, ct.HARDWARE_ERROR_STATUS) == 1 << ct.OVERLOAD_BIT
    bus.reboot(1)
    assert bus.read(1, ct.HARDWARE_ERROR_STATUS) == 0
    assert emu.snapshot(1).torque_enabled is False


@pytest.mark.parametrize(
    ("item", "value"),
    [
        (ct.GOAL_VELOCITY, -230),
        (ct.GOAL_VELOCITY, 230),
        (ct.HOMING_OFFSET, -1024),
        (ct.GOAL_POSITION, -(2**31)),
        (ct.GOAL_POSITION, 2**31 - 1),
    ],
)
def test_signed_values_round_trip_over_the_wire(bus, item, value):
    bus.write(1, ct.OPERATING_MODE, ct.EXTENDED_POSITION_MODE)
    bus.write(1, item, value)
    assert bus.read(1, item) == value


def test_present_position_goes_negative_when_turning_backwards(bus):
    bus.write(1, ct.OPERATING_MODE, ct.VELOCITY_MODE)
    bus.write(1, ct.TORQUE_ENABLE, 1)
    bus.write(1, ct.GOAL_VELOCITY, -230)
    time.sleep(0.2)
    position = bus.read(1, ct.PRESENT_POSITION)
    velocity = bus.sync_read(ct.STATE_BLOCK, [1])[1].values["present_velocity"]
    assert position < -100
    assert velocity == -230


def test_eeprom_write_with_torque_on_is_an_access_error(bus):
    bus.write(1, ct.TORQUE_ENABLE, 1)
    with pytest.raises(DeviceError, match="motor 1: write operating_mode=1 refused: access error"):
        bus.write(1, ct.OPERATING_MODE, ct.VELOCITY_MODE)


def test_goal_velocity_above_the_limit_is_a_data_limit_error(bus):
    with pytest.raises(DeviceError, match="data limit error") as info:
        bus.write(2, ct.GOAL_VELOCITY, 231)
    assert info.value.motor_id == 2 and info.value.number == 6


def test_missing_motor_is_named(bus):
    with pytest.raises(MotorNotResponding, match="motor 9 did not answer"):
        bus.ping(9)
    with pytest.raises(MotorNotResponding, match="motor 7 did not answer") as info:
        bus.sync_read(ct.STATE_BLOCK, [1, 7, 2])
    assert info.value.motor_id == 7


def test_corrupt_reply_fails_without_retries_and_passes_with_them(emu):
    with DxlBus(emu.port, 1_000_000, retries=0) as bus:
        emu.corrupt_replies(2, 1)
        with pytest.raises(CommError, match="motor 2: read model_number failed"):
            bus.read(2, ct.MODEL_NUMBER)
    with DxlBus(emu.port, 1_000_000, retries=2) as bus:
        emu.corrupt_replies(2, 1)
        emu.drop_replies(3, 1)
        assert bus.read(2, ct.MODEL_NUMBER) == ct.MX28_MODEL_NUMBER
        assert bus.read(3, ct.MODEL_NUMBER) == ct.MX28_MODEL_NUMBER


def test_sync_read_resends_after_a_lost_reply_when_retries_allow(emu):
    with DxlBus(emu.port, 1_000_000, retries=2) as bus:
        emu.drop_replies(2, 1)
        with pytest.raises(MotorNotResponding, match=r"motor 2 did not answer \(sync read\)"):
            bus.sync_read(ct.STATE_BLOCK, IDS, retries=0)
        emu.drop_replies(2, 1)
        emu.corrupt_replies(2, 1)  # consumed by the round after the lost reply
        statuses = bus.sync_read(ct.STATE_BLOCK, IDS)
    assert sorted(statuses) == IDS
    assert all(s.values["present_velocity"] == 0 for s in statuses.values())
    sync_reads = [q for q in emu.packets() if q.instruction == p.SYNC_READ]
    assert len(sync_reads) == 4  # one without retries, then lost, corrupt, answered


def test_port_has_one_owner(bus, emu):
    with pytest.raises(PortError, match="cannot open port"):
        DxlBus(emu.port, 1_000_000).open()


def test_status_return_level_zero_leaves_only_ping_answered(bus, emu):
    with pytest.raises(MotorNotResponding, match="motor 3"):
        bus.write(3, ct.STATUS_RETURN_LEVEL, 0)
    assert bus.ping(3) == ct.MX28_MODEL_NUMBER
    with pytest.raises(MotorNotResponding, match="motor 3"):
        bus.read(3, ct.OPERATING_MODE)
