"""A live AFC: the campaign's measured points so far as a Prefect markdown artifact.

:class:`LiveAfc` takes each step's :class:`~vibid.acquisition.campaign.StepProgress` and,
at most every ``min_interval_s`` of wall time (always on the last step and on
:meth:`LiveAfc.close`), draws |H| and phase against frequency (the points so far, a model
over them once there is one) and publishes it as a new version of the markdown artifact
``<specimen>-live``, the PNG embedded as a ``data:`` URI, so the Prefect UI shows the test's
progress without stopping it.

Cost: one update that publishes renders a small figure (Agg, no pyplot: nothing kept
between figures) and makes one API call. Besides ``min_interval_s``, the next publication
waits at least ``cost / max_share`` after the last one (``cost``: what that one took), so on
average the live AFC takes at most ``max_share`` (2 %) of the campaign's wall time, whatever
the machine or the server (the first publication, which pays for the imports, does not
count). A publication that fails (no run context, the server gone) is
logged once as a warning and never raised: the campaign goes on.
"""

from __future__ import annotations

import io
import logging
import math
import time
from datetime import UTC, datetime

import numpy as np

log = logging.getLogger("vibid.flows")

#: The share of wall time the live AFC may take on average (render + publish).
MAX_SHARE = 0.02


def prefect_publish(key: str, markdown: str) -> None:
    """Publish ``markdown`` as a new version of the markdown artifact ``key``."""
    from prefect.artifacts import create_markdown_artifact

    create_markdown_artifact(
        key=key, markdown=markdown, description="live AFC of the running campaign"
    )


def _optional(p, *names) -> float | None:
    """The first finite attribute of ``p`` among ``names`` (StepProgress may not carry it)."""
    for name in names:
        v = getattr(p, name, None)
        if v is not None:
            try:
                v = float(v)
            except (TypeError, ValueError):
                continue
            if math.isfinite(v):
                return v
    return None


class LiveAfc:
    """The live AFC of one campaign (see the module's text).

    ``publish(key, markdown)`` defaults to :func:`prefect_publish`; ``clock`` (seconds,
    monotonic) to :func:`time.monotonic`; ``max_share`` None turns the cost rule off.
    """

    def __init__(
        self,
        specimen: str,
        n_steps: int,
        *,
        min_interval_s: float = 2.0,
        publish=None,
        clock=None,
        max_share: float | None = MAX_SHARE,
        logger=None,
        plan: str = "",
    ):
        from vibid.report import artifact_key

        self.specimen = specimen or "specimen"
        self.key = artifact_key(specimen, "live")
        self.n_steps = int(n_steps)
        #: an adaptive campaign's rule (its steps to come are not known: ``n_steps`` is
        #: what it has planned so far), or "" for a campaign of fixed steps
        self.plan = plan
        self.min_interval_s = float(min_interval_s)
        self.max_share = max_share
        self.publish = publish or prefect_publish
        self.clock = clock or time.monotonic
        self.logger = logger or log
        #: step index -> (frequency Hz, |H|, phase deg, std of |H| or None); a re-recorded
        #: step replaces its first record
        self.points: dict[int, tuple[float, float, float, float | None]] = {}
        self.stand_time_s: float | None = None
        self.eta_s: float | None = None
        self.last = None
        self.model: tuple[np.ndarray, np.ndarray, np.ndarray | None, str] | None = None
        self.note = ""
        self.published = 0  # publications made
        self.failed = False  # a publication failed (warned once)
        self.costs: list[float] = []  # seconds per render + publish (failed ones too)
        self._next_at: float | None = None  # no publication before this clock time
        self._dirty = False  # an update not published yet
        # the imports now, before the campaign, not in its first step (a few seconds)
        import matplotlib.backends.backend_agg  # noqa: F401
        import matplotlib.figure  # noqa: F401

        if publish is None:
            import prefect.artifacts  # noqa: F401

    # -- input ----------------------------------------------------------------------------
    def update(self, progress) -> bool:
        """Record one written step; publish if due. True when it published. Never raises."""
        try:
            p = progress
            self.n_steps = int(getattr(p, "n_steps", self.n_steps) or self.n_steps)
            std = _optional(p, "h_std", "h_abs_std")
            self.points[int(p.index)] = (
                float(p.frequency_hz),
                float(p.h_abs),
                float(p.phase_deg),
                std,
            )
            total = _optional(p, "stand_time_s")
            step = [_optional(p, n) for n in ("settle_s", "record_s")]
            if total is not None:
                self.stand_time_s = total
            elif any(v is not None for v in step):
                self.stand_time_s = (self.stand_time_s or 0.0) + sum(v or 0.0 for v in step)
            self.eta_s = _optional(p, "eta_s")
            self.last = p
            self._dirty = True
            last_step = int(p.index) + 1 >= self.n_steps
            if last_step or self._next_at is None or self.clock() >= self._next_at:
                return self._publish()
        except Exception as exc:  # the campaign must go on
            self._warn(exc)
        return False

    def add_recorded(self, afc, stand_time_s: float | None = None) -> None:
        """The steps a resumed campaign's file holds already (an
        :class:`~vibid.signal.afc.AfcTable`) and the stand time they took, so that the live
        AFC shows the whole test, not only this process's part of it."""
        for p in afc.points:
            h = complex(p.h)
            if math.isfinite(p.commanded_hz) and math.isfinite(abs(h)):
                std = float(p.std) if math.isfinite(p.std) else None
                self.points[int(p.index)] = (
                    float(p.commanded_hz),
                    abs(h),
                    math.degrees(math.atan2(h.imag, h.real)),
                    std,
                )
        if stand_time_s is not None:
            self.stand_time_s = float(stand_time_s)
        self._dirty = bool(self.points)

    def set_model(self, frequency_hz, H, *, label: str = "model", magnitude_only: bool = False):
        """A model's AFC to draw over the points from the next publication on (``H``
        complex; with ``magnitude_only`` its |H| alone, no phase). Its phase is unwrapped
        along ``frequency_hz`` (as the report's AFC figure draws it)."""
        f = np.asarray(frequency_hz, float)
        H = np.asarray(H)
        ok = np.isfinite(f) & np.isfinite(H)
        order = np.argsort(f[ok])
        f, H = f[ok][order], H[ok][order]
        phase = None if magnitude_only else np.degrees(np.unwrap(np.angle(H)))
        self.model = (f, np.abs(H), phase, label)
        self._dirty = True

    def set_identified(self, result, setup=None, *, label: str = "identified model") -> None:
        """The identification's model (an ``IdentificationResult``) on the fine grid of the
        report's AFC figure (:func:`vibid.identify.assess.curve.model_curve`: its resonances drawn
        at their height) over the measured band; computed here, once, not at each step.
        Without ``setup`` (the session's :class:`~vibid.setup_model.Setup`), on the used
        points alone."""
        try:
            magnitude_only = bool(getattr(result, "magnitude", False))
            if setup is not None:
                from vibid.identify.assess.curve import model_curve

                f, H, _ = model_curve(setup, result)
            else:
                used = np.asarray(result.used, bool)
                f, H = np.asarray(result.frequency_hz)[used], np.asarray(result.model_afc)[used]
            self.set_model(f, H, label=label, magnitude_only=magnitude_only)
        except Exception as exc:  # a figure is never worth stopping the flow for
            self._warn(exc)

    def show(self, note: str = "") -> bool:
        """Publish now if anything (or ``note``) is new since the last publication (an
        adaptive campaign's new fit between batches). Never raises."""
        if note:
            self.note, self._dirty = note, True
        if not self._dirty or not self.points:
            return False
        try:
            return self._publish()
        except Exception as exc:
            self._warn(exc)
            return False

    #: the campaign's end: the last publication, if anything is new
    close = show

    # -- output ---------------------------------------------------------------------------
    def figure(self):
        """The points so far (and the model) as a figure: |H| (log) and phase against
        frequency, the phase unwrapped as in the report's AFC figure (the model's along its
        grid, each measured one within half a turn of the model's; without a model phase
        the measured ones unwrapped along frequency)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        from vibid.report.plots import H_UNIT, phase_near

        idx = sorted(self.points, key=lambda i: self.points[i][0])
        f = np.array([self.points[i][0] for i in idx])
        mag = np.array([self.points[i][1] for i in idx])
        ph = np.radians([self.points[i][2] for i in idx])
        std = [self.points[i][3] for i in idx]
        model = self.model
        if model is not None and model[2] is not None and len(model[0]):
            ph = phase_near(ph, np.interp(f, model[0], np.radians(model[2])))
        else:
            ph = np.unwrap(ph)
        fig = Figure(figsize=(6.4, 4.4))
        FigureCanvasAgg(fig)
        ax1, ax2 = fig.subplots(2, 1, sharex=True)
        if std and all(s is not None for s in std):
            s = np.array(std, float)
            ax1.fill_between(
                f,
                np.maximum(mag - 2 * s, mag * 1e-3),
                mag + 2 * s,
                color="C0",
                alpha=0.25,
                lw=0,
                label="±2 std",
            )
        ax1.plot(f, mag, "o", ms=3, color="C0", label="measured")
        ax2.plot(f, np.degrees(ph), "o", ms=3, color="C0")
        if model is not None:
            mf, mm, mp, label = model
            ax1.plot(mf, mm, "-", lw=1, color="C3", label=label)
            if mp is not None:
                ax2.plot(mf, mp, "-", lw=1, color="C3")
        if np.any(mag > 0):
            ax1.set_yscale("log")
        ax1.set_ylabel(f"|H| ({H_UNIT})")
        ax2.set_ylabel("phase (deg)")
        ax2.set_xlabel("frequency (Hz)")
        ax1.legend(loc="upper right", fontsize=7)  # "best" searches: slow with many points
        ax1.set_title(
            f"{self.specimen}: {len(self.points)} steps"
            if self.plan
            else f"{self.specimen}: {len(self.points)} of {self.n_steps} steps",
            fontsize=9,
        )
        for ax in (ax1, ax2):
            ax.grid(True, alpha=0.3)
        fig.subplots_adjust(left=0.13, right=0.97, top=0.93, bottom=0.11, hspace=0.08)
        return fig

    def render_png(self, dpi: int = 80) -> bytes:
        """:meth:`figure` as a PNG."""
        fig = self.figure()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi)
        fig.clear()
        return buf.getvalue()

    def markdown(self, png: bytes | None = None) -> str:
        """The artifact's text: steps done and to go, times, the last step, the figure."""
        done = (int(self.last.index) + 1) if self.last is not None else len(self.points)
        done = max(done, len(self.points))
        now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
        lines = [f"# {self.specimen}: live AFC", ""]
        if self.plan:
            lines += [
                f"- {self.plan}",
                f"- steps done {done} ({max(self.n_steps - done, 0)} more planned in this batch)",
            ]
        else:
            lines.append(
                f"- steps done {done} of {self.n_steps} ({max(self.n_steps - done, 0)} to go)"
            )
        if self.stand_time_s is not None:
            lines.append(f"- stand time so far: {self.stand_time_s:.1f} s")
        if self.eta_s is not None and done < self.n_steps:
            lines.append(f"- about {self.eta_s:.0f} s left")
        if self.last is not None:
            p = self.last
            lines.append(
                f"- last step: {p.frequency_hz:.2f} Hz, |H| {p.h_abs:.4g}, "
                f"phase {p.phase_deg:.1f} deg, {getattr(p, 'status', '')}"
            )
        if self.model is not None:
            lines.append(f"- drawn over the points: {self.model[3]}")
        if self.note:
            lines.append(f"- {self.note}")
        lines.append(f"- updated {now}")
        if png is not None:
            from vibid.report.plots import png_data_uri

            lines += ["", f"![live AFC of {self.specimen}]({png_data_uri(png)})"]
        return "\n".join(lines) + "\n"

    def _publish(self) -> bool:
        t0 = self.clock()
        try:
            self.publish(self.key, self.markdown(self.render_png()))
            ok = True
        except Exception as exc:
            self._warn(exc)
            ok = False
        t1 = self.clock()
        cost = max(t1 - t0, 0.0)
        self.costs.append(cost)
        wait = self.min_interval_s
        if self.max_share and len(self.costs) > 1:
            # (the first one pays for importing matplotlib and the client: not a measure)
            wait = max(wait, cost / self.max_share)
        self._next_at = t1 + wait
        self._dirty = not ok
        self.published += ok
        return ok

    def _warn(self, exc: BaseException) -> None:
        if not self.failed:
            self.failed = True
            self.logger.warning(
                "live AFC %s not published (the campaign goes on): %s: %s",
                self.key,
                type(exc).__name__,
                exc,
            )
