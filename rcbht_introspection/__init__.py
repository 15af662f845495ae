"""rcbht_introspection: robot introspection of contact tasks through the RCBHT wrench action grammar."""

__version__ = "0.1.0"
