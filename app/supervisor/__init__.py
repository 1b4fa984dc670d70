"""The in-vehicle service: health, systemd notification, status, and the loop that wires them."""
