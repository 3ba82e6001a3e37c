"""A progress bar on stderr for the identification's searches (the core only calls back)."""

from __future__ import annotations

from contextlib import contextmanager


@contextmanager
def search_progress(enabled: bool = True):
    """Yield a ``progress(label, done, total, best)`` callback drawing a tqdm bar per search
    (``best`` None for work that is not a search: counted in steps), or None when disabled;
    the bars are closed on exit."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm

    bars: dict = {}

    def progress(label: str, done: int, total: int, best: float | None) -> None:
        bar = bars.get(label)
        if bar is None:
            bar = bars[label] = tqdm(
                total=total,
                desc=label,
                unit="gen" if best is not None else "step",
                leave=False,
                dynamic_ncols=True,
            )
        bar.update(done - bar.n)
        if best is not None:
            bar.set_postfix(best=f"{best:.4g}")

    try:
        yield progress
    finally:
        for bar in bars.values():
            bar.close()
