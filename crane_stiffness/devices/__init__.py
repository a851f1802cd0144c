"""Device emulators: the simulated physics served through the real devices' protocols on this machine, so that
``driver ← device protocol ← simulated physics`` runs end to end without hardware. Pure Python, no ROS.

- :mod:`.rdt_device` — an ATI Net F/T / OnRobot HEX over RDT (UDP), with ``/netftapi2.xml`` and fault injection.
- :mod:`.modbus_device` — a LabJack / ADAM-style analog input over Modbus TCP, on pymodbus's server.
"""
