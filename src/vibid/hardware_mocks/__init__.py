"""hardware_mocks: the stand without hardware, behind the real drivers.

* :mod:`~vibid.hardware_mocks.sim_generator` and :mod:`~vibid.hardware_mocks.protocol_vibidsim`
  — a simulated SCPI generator reached with ``serial.serial_for_url("vibidsim://NAME")``;
* :mod:`~vibid.hardware_mocks.fake_daq` — a fake ``nidaqmx.Task`` for the real DAQ driver;
* :mod:`~vibid.hardware_mocks.specimen` — the virtual specimen (the plate model, any effects);
* :mod:`~vibid.hardware_mocks.virtual_stand` — all of it wired into one stand
  (``open_simulated_stand``), with record impairments and a virtual clock;
* :mod:`~vibid.hardware_mocks.records`, :mod:`~vibid.hardware_mocks.simulated_session` — pure
  record synthesis and whole simulated sessions (``vibid simulate``).

Importing this package registers it as a pyserial protocol handler package, so that the
``vibidsim://`` scheme is known to ``serial.serial_for_url``; nothing is built at import.
"""

try:
    import serial as _serial
except ImportError:  # pragma: no cover - pyserial is a dependency
    _serial = None
if _serial is not None and __name__ not in _serial.protocol_handler_packages:
    _serial.protocol_handler_packages.append(__name__)
