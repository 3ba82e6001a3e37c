"""The virtual specimen: the declared plate as the full FE model, with its true parameters.

One home for the physics of every simulated record: :func:`vibid.hardware_mocks.
simulated_session.true_afc` (``vibid simulate``) and the virtual stand
(:mod:`vibid.hardware_mocks.virtual_stand`, the simulated campaign) both ask a
:class:`VirtualSpecimen` for ``H(f)``.

``params`` holds the material's true parameters and any effect's (e.g.
``k_theta_N_per_rad``, ``tau_s``): those effects are in the specimen whatever the declared
setup says. The model is the full (sparse) finite-element model, not the reduced one the
identification uses, on a mesh chosen for ``f_max_hz`` at ``accuracy``.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from vibid.identify.model.assembly import Geometry, model_matrices
from vibid.identify.model.full import model_afc_full
from vibid.identify.model.mesh import discretisation
from vibid.identify.model.modal import frequencies_and_decays, model_eigenvalues
from vibid.identify.model.plate import plate_model_for
from vibid.identify.model.terms import theta_from_dict
from vibid.setup_model import Setup


class VirtualSpecimen:
    """The plate of ``setup`` with the true ``params``.

    Parameters
    ----------
    setup : the declared setup (geometry, density, the response sensor's mass and place).
    params : true parameters: the material's and any effect's.
    f_max_hz : the highest frequency the mesh must resolve, Hz.
    accuracy : mesh accuracy (``"default"``, ``"fine"``, ...; see ``identify.model.forward``).
    effects : effect names to include besides those ``params`` implies (an effect without
        parameters of its own, such as ``transverse_shear`` on an isotropic plate).
    """

    def __init__(
        self, setup: Setup, params: dict, *, f_max_hz: float, accuracy: str = "fine", effects=()
    ):
        self.setup = setup
        self.f_max_hz = float(f_max_hz)
        self.params = dict(params)
        geometry = Geometry.from_setup(setup)
        self.model = plate_model_for(self.params, effects).for_geometry(geometry)
        self.theta = theta_from_dict(self.model, self.params)
        D = np.asarray(self.model.moduli(self.theta), float)
        disc = discretisation(
            geometry, accuracy, f_max_hz=float(f_max_hz), rigidity_n_m=float(min(D[0], D[3]))
        )
        self.matrices = model_matrices(geometry, disc, tuple(self.model.effects))
        self._cache: dict[float, complex] = {}

    def h(self, frequencies_hz) -> np.ndarray:
        """The AFC (response over base acceleration, complex) at ``frequencies_hz`` (Hz);
        each frequency is solved once and remembered."""
        freqs = np.atleast_1d(np.asarray(frequencies_hz, float))
        todo = np.array(sorted({float(f) for f in freqs if float(f) not in self._cache}))
        if todo.size:
            values = model_afc_full(self.matrices, self.model, self.theta, todo)
            self._cache.update(zip(todo.tolist(), values.tolist()))
        return np.array([self._cache[float(f)] for f in freqs], dtype=complex)

    @cached_property
    def modes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(natural frequency Hz, decay rate 1/s)`` of the first modes: a free vibration
        of mode ``k`` decays as ``exp(-γ_k t)``."""
        n = 12
        return frequencies_and_decays(model_eigenvalues(self.matrices, self.model, self.theta, n))

    def nearest_mode(self, frequency_hz: float) -> tuple[float, float]:
        """``(f_n Hz, γ_n 1/s)`` of the mode nearest ``frequency_hz``."""
        f_n, gamma = self.modes
        k = int(np.argmin(np.abs(f_n - frequency_hz)))
        return float(f_n[k]), float(gamma[k])
