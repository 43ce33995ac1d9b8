"""What the simulator and the vessel computer share without importing each other.

The wire contract (MAVLink dialect and framing, UDP endpoints, geodesy that turns NED metres into
WGS-84 on the wire) and small configuration helpers. Imports nothing else of this project.
"""
