"""The generator driver against a real instrument: skipped unless VIBID_GENERATOR_URL names
one (e.g. ``VIBID_GENERATOR_URL=/dev/ttyUSB0 pytest tests/test_stand_generator_with_device.py``).

Keep the shaker unloaded or the amplifier off: the tests switch the output on at 10 mV.
"""

import os

import pytest

from vibid.acquisition.generator import GeneratorError, open_generator

URL = os.environ.get("VIBID_GENERATOR_URL")
pytestmark = pytest.mark.skipif(not URL, reason="no generator: set VIBID_GENERATOR_URL")


@pytest.fixture
def generator():
    gen = open_generator(URL, timeout_s=2.0, max_vpp=0.1)
    gen.shutdown()  # output off before ...
    yield gen
    gen.close()  # ... and after each test


def test_identifies_itself(generator):
    assert generator.idn.count(",") >= 3


@pytest.mark.parametrize(
    "name, value",
    [
        ("frequency_hz", 123.4),
        ("amplitude_vpp", 0.01),
        ("output_enabled", True),
        ("output_enabled", False),
    ],
)
def test_setting_reads_back(generator, name, value):
    setattr(generator, name, value)
    assert getattr(generator, name) == pytest.approx(value)


def test_out_of_range_is_refused_before_sending(generator):
    with pytest.raises(GeneratorError, match="nothing was sent"):
        generator.amplitude_vpp = 1.0
