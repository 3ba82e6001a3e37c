"""The real titanium AFC's points that the titanium benchmarks fit: every fifth point of
the AFC and every point of its two resonances (180-215 Hz, 1255-1300 Hz), about 2900 of
its 11 960 (``titanium_sensor.py``, ``titanium_models.py``)."""

from __future__ import annotations

import numpy as np


def titanium_subset(data_dir: str):
    """(declared setup, all frequencies (Hz), the kept frequencies (Hz), H, std) of
    ``data_dir``'s ``setup.json`` and ``afc.csv``."""
    from vibid.setup_model import parse_setup
    from vibid.signal.imported import read_afc_csv

    setup = parse_setup(open(f"{data_dir}/setup.json").read())
    afc = read_afc_csv(f"{data_dir}/afc.csv")
    f_all = afc.frequency_hz
    keep = np.zeros(f_all.size, bool)
    keep[::5] = True
    keep |= ((f_all > 180) & (f_all < 215)) | ((f_all > 1255) & (f_all < 1300))
    return setup, f_all, f_all[keep], afc.H[keep], afc.std[keep]
