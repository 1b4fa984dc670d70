"""Headway's CAN layer: its messages (``dbc/headway.dbc``), packer and parser, vehicle inputs,
sending and logging, scheduling, and CAN-log replay. Independent of the C++ core."""
from .bus import CanBusError, CanOutput, open_bus
from .database import HEADWAY_DBC, DbcError, headway_database, load_dbc
from .log_replay import CanLogError, CanLogReader
from .packer import CanPacker
from .parser import CanParser
from .scheduler import CanScheduler
from .session import CanSession
from .vehicle_input import VehicleInput, VehicleInputError, VehicleState

__all__ = ["HEADWAY_DBC", "CanBusError", "CanLogError", "CanLogReader", "CanOutput", "CanPacker", "CanParser",
           "CanScheduler", "CanSession", "DbcError", "VehicleInput", "VehicleInputError", "VehicleState",
           "headway_database", "load_dbc", "open_bus"]
