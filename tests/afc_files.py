"""AFC files for the import tests: the CSV of ``vibid identify --afc`` (columns
``frequency_hz, re, im[, std]``), every number written as its exact shortest repr."""

from __future__ import annotations


def write_afc_csv(path, f, H, std=None):
    """Write ``f`` (Hz), complex ``H`` and the optional ``std`` to ``path``; returns it."""
    lines = ["frequency_hz,re,im" + (",std" if std is not None else "")]
    for k in range(len(f)):
        row = f"{float(f[k])!r},{float(H[k].real)!r},{float(H[k].imag)!r}"
        lines.append(row + (f",{float(std[k])!r}" if std is not None else ""))
    path.write_text("\n".join(lines) + "\n")
    return path
