"""Real-hardware drivers, pure Python/numpy with no ROS import (the nodes in :mod:`crane_stiffness.nodes` wrap them).

- :mod:`.rdt` — ATI Net F/T / Axia / OnRobot HEX Raw Data Transfer: request and record codec, vectorised decoding,
  counts → N and N·m, sequence accounting (lost, out of order, duplicates), ``netftapi2.xml`` parsing.
- :mod:`.rdt_client` — the UDP stream: receiver thread, kernel arrival stamps, reconnect.
- :mod:`.rdt_pipeline` — datagrams to wrenches: sequence accounting, stamps, tare, block averaging.
- :mod:`.clock` — a device sample counter mapped to host time, with drift tracking on the lower envelope of the
  arrival times.
- :mod:`.modbus` — analog-input register decoding (float32 / int16 / …, word order, scaling to metres) and the
  Modbus TCP poller.
- :mod:`.errors` — the package's exceptions.
"""
