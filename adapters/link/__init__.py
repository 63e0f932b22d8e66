"""The live link: MAVLink telemetry from a vehicle (UDP, TCP, serial) parsed as it arrives
(:mod:`adapters.link.mavlink`), and aligned onto a mapping's grid by the offline import's rules
(:mod:`adapters.link.online`)."""
