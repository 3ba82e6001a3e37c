"""AFC files for the import tests: the CSV of ``vibid identify --afc`` (columns
``frequency_hz, re, im[, std]``), every number written as its exact shortest repr, and
type-58 records as another system writes them (pyuff directly)."""

from __future__ import annotations


def csv_lines(f, H, std=None) -> list[str]:
    """The header and one line per point of the CSV of ``f`` (Hz), complex ``H`` and the
    optional ``std``, in the order given."""
    lines = ["frequency_hz,re,im" + (",std" if std is not None else "")]
    for k in range(len(f)):
        row = f"{float(f[k])!r},{float(H[k].real)!r},{float(H[k].imag)!r}"
        lines.append(row + (f",{float(std[k])!r}" if std is not None else ""))
    return lines


def write_afc_csv(path, f, H, std=None):
    """Write ``f`` (Hz), complex ``H`` and the optional ``std`` to ``path``; returns it."""
    path.write_text("\n".join(csv_lines(f, H, std)) + "\n")
    return path


def write_pyuff_record(path, x, data, *, spacing, binary=0, id1="other system"):
    """Append a type-58 record as another system would write it (pyuff directly): uneven
    abscissa ``x`` (Hz) with ``spacing`` 0, even (``x[0]`` and ``x[1] - x[0]`` as E13.5)
    with 1; complex or real ``data``; returns ``path``."""
    import pyuff

    record = {
        "type": 58,
        "binary": binary,
        "func_type": 4,
        "id1": id1,
        "rsp_node": 1,
        "rsp_dir": 3,
        "ref_node": 1,
        "ref_dir": 3,
        "abscissa_spacing": spacing,
        "abscissa_spec_data_type": 18,
        "ordinate_spec_data_type": 12,
        "orddenom_spec_data_type": 13,
        "z_axis_spec_data_type": 0,
        "x": x,
        "data": data,
    }
    pyuff.UFF(str(path)).write_sets(record, mode="add")
    return path
