"""Opening buses from the configuration: clear errors that say what to do; the live session on a
python-can virtual bus takes the ego speed from the bus and sends Headway's frames there."""
from __future__ import annotations

import time

import can
import cantools
import pytest

from app.can import CanBusError, CanOutput, CanPacker, CanParser, CanSession, headway_database, open_bus
from app.bench.can_output import fake_result
from app.can.config_schema import defaults
from tests.conftest import REPO

EGO_DBC = REPO / "app" / "sim" / "ego_speed_placeholder.dbc"


def socketcan_missing() -> bool:
    try:
        open_bus("socketcan", "vcan0").shutdown()
        return False
    except CanBusError as exc:
        return "this kernel has no SocketCAN" in str(exc)


@pytest.mark.skipif(not socketcan_missing(), reason="this machine has SocketCAN; the error case cannot happen")
def test_socketcan_without_kernel_support_says_what_to_do():
    with pytest.raises(CanBusError) as e:
        open_bus("socketcan", "can0")
    text = str(e.value)
    assert "socketcan channel can0: cannot be opened" in text
    assert "interface: virtual" in text and "modprobe" in text


def test_unknown_interface_and_missing_adapters_are_clear_errors():
    with pytest.raises(CanBusError, match="python-can does not know interface 'nosuch'"):
        open_bus("nosuch", "x")
    with pytest.raises(CanBusError, match="cannot be opened"):
        open_bus("pcan", "PCAN_USBBUS1")  # no vendor library here, or no adapter


def test_unknown_output_log_format(tmp_path):
    with pytest.raises(CanBusError, match=r"unknown CAN log format '\.txt': use \.log \(candump\), \.asc or \.blf"):
        CanOutput(None, tmp_path / "out.txt")


def test_live_session_on_a_virtual_bus(tmp_path):
    cfg = defaults()
    cfg["can"].update(interface="virtual", channel="live-test", output_log=str(tmp_path / "live.log"))
    cfg["vehicle"].update(dbc=str(EGO_DBC), speed_message="EGO_SPEED", speed_signals="SPEED_MPS")
    ego = cantools.database.load_file(str(EGO_DBC)).get_message_by_name("EGO_SPEED")
    with can.Bus(interface="virtual", channel="live-test") as car, CanSession.for_live(cfg) as s:
        now = time.time()
        assert s.vehicle_state(now).speed_mps is None
        car.send(can.Message(arbitration_id=ego.frame_id, is_extended_id=False,
                             data=ego.encode({"SPEED_MPS": 27.5, "COUNTER": 0})))
        time.sleep(0.05)
        state = s.vehicle_state(time.time())
        assert state.speed_mps == pytest.approx(27.5)
        sent = s.publish(time.time(), fake_result(0, 2),
                         fcw={"level": 1, "available": True, "ttc_s": 2.2, "ttc_source": "range"})
        assert [m.arbitration_id for m in sent][:3] == [0x600, 0x601, 0x602]
        parser = CanParser(headway_database())
        while (msg := car.recv(timeout=0.2)) is not None:
            parser.update(msg)
    assert parser.accepted == len(sent) and not parser.drops
    assert parser.values("HW_FCW")["FCW_LEVEL"] == 1 and parser.values("HW_STATUS")["STATE"] == 1
    assert len((tmp_path / "live.log").read_text().splitlines()) == len(sent)


def test_a_bus_that_fails_to_send_does_not_stop_the_rest(tmp_path):
    packer = CanPacker(headway_database())
    with can.Bus(interface="virtual", channel="fail-test") as bus:
        out = CanOutput(bus, tmp_path / "o.log")
        bus.shutdown()  # sending on a closed bus raises
        assert out.send([packer.pack("HW_STATUS", {"STATE": 1})], now_s=5.0) == 0
        assert out.send_errors == 1 and out.tx_error(5.5, 1.0) and not out.tx_error(6.5, 1.0)
        out.close()
