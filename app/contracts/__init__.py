"""What the parts of the Python side agree on, defined once at the bottom of its layers (tests/test_layers.py):
the FCW levels, the TTC sources, the fault registry and overall states, and the form of a configuration key.
Everything here imports only the standard library, so the CAN layer, the supervisor, the configuration and
the cabin-MCU link (firmware_bridge) can all import it without importing each other."""
