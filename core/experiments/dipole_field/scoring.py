"""The errors of one run of the field filter against the analytic field (RMSE, eq 3.42,
per zone and component; the imaginary part a quarter period later, the magnitude from
the two), the RLS baseline, the amplitude-only fit and the figure's slices."""

from __future__ import annotations

import numpy as np

from estim.experiments.dipole import COMPONENTS, sinusoid_rls
from estim.experiments.dipole_field.config import (
    EULER,
    FIT,
    KF,
    PLAIN,
    RLS,
    SLICE_LABELS,
    SOURCE_ONLY,
)
from estim.fields import wave
from estim.util import lazy

spatial = lazy.load("scipy.spatial")
fdtd = lazy.load("estim.fields.fdtd")
grids = lazy.load("estim.fields.grid")


def amplitude_fit(measured: np.ndarray, basis_sensors: list, basis_traces: list) -> list:
    """The amplitude-only fit: the one complex source amplitude ``a`` whose simulation best
    fits every reading of the record in least squares (the simulation is linear in ``Re a``
    and ``Im a``: two basis runs, driven by 1 and by j), then its fields. It sees the whole
    record at once (a smoother, not a filter: the source-only filter beats it in some cells)."""
    G = np.stack(basis_sensors)                    # (steps, 2 basis, sensors, 6)
    y = measured.reshape(len(G), 6, -1).transpose(0, 2, 1)
    design = G.transpose(1, 0, 2, 3).reshape(2, -1).T
    coef = np.linalg.lstsq(design, y.ravel(), rcond=None)[0]
    return [{F: coef[0] * b[F][:1] + coef[1] * b[F][1:] for F in ("E", "H")}
            for b in basis_traces]


def smoothed(measured: np.ndarray, times: np.ndarray, omega: float, rls: dict) -> np.ndarray:
    """The RLS baseline on every sensor's time series, shaped like ``measured``."""
    series = measured.reshape(len(times), -1).T[:, :, None]    # (sensors x 6, steps, 1)
    return sinusoid_rls(series, times, omega, rls)[..., 0].T.reshape(measured.shape)


def figure_slices(grid, phasors, dipole, times, traces) -> dict:
    """|E| and |H| in the plane through the source nearest y = 0 at the last recorded step:
    the analytic truth, the field filter's mean, the amplitude-only fit and the field
    filter's error; points within two cells of the source are left blank."""
    n = grid.n
    plane = np.flatnonzero(np.isclose(grid.xyz[:, 1], grid.axis[n // 2]))
    turn = np.exp(1j * dipole.omega * times[-1])
    truth = analytic_cartesian(grid, phasors, turn, plane)
    kf = np.stack([traces[KF][-1]["E"][0][:, plane], traces[KF][-1]["H"][0][:, plane]])
    fit = np.stack([traces[FIT][-1]["E"][0][:, plane], traces[FIT][-1]["H"][0][:, plane]])
    blank = grid.r[plane] < 2 * grid.spacing
    out = {"labels": SLICE_LABELS}
    for i, field_name in enumerate(("E", "H")):
        for label, data in zip(SLICE_LABELS, (truth[i], kf[i], fit[i], kf[i] - truth[i]),
                               strict=True):
            mag = np.linalg.norm(data, axis=0)
            mag[blank] = np.nan
            out[f"{field_name}|{label}"] = mag.reshape(n, n)
    out["extent"] = [grid.axis[0], grid.axis[-1], grid.axis[0], grid.axis[-1]]
    out["time"] = float(times[-1])
    return out


class EulerRun:
    """The plain simulation with the thesis' forward Euler (``F ~ I + T F`` for eq 5.20's
    system) on ``(u, u')`` for ``u = [A_z, Phi]``, nominal source, Mur faces not applied
    (Euler has no two-level boundary of that kind); it grows without bound and is reported
    as it comes out."""

    def __init__(self, sim: fdtd.Simulation, amplitude: complex) -> None:
        self.sim, self.amplitude = sim, np.array([amplitude])
        self.u = np.zeros((1, 2, sim.grid.size))
        self.v = np.zeros_like(self.u)

    def step(self, t: float) -> None:
        L = self.sim.grid.laplacian
        s = np.zeros_like(self.u)
        s[..., self.sim._support] = self.sim.source(t, self.amplitude)
        with np.errstate(all="ignore"):
            self.u, self.v = wave.step(self.u, self.v,
                                       lambda x: (L @ x.reshape(-1, x.shape[-1]).T).T.reshape(
                                           x.shape),
                                       self.sim.dipole.c, self.sim.dt, s_now=s,
                                       method="euler")

    def fields(self) -> dict:
        with np.errstate(all="ignore"):
            return fdtd.fields_from(self.sim.grid, self.u[:, 0], self.u[:, 1], self.v[:, 0],
                               self.sim.dipole.mu0)


def analytic_cartesian(grid: grids.Grid, phasors: dict, turn: complex,
                        where: np.ndarray) -> np.ndarray:
    """Analytic E and H at ``where`` as ``(2, 3, points)`` Cartesian components."""
    th, ph = grid.theta[where], grid.phi[where]
    Er = (phasors["E_r"][where] * turn).real
    Et = (phasors["E_theta"][where] * turn).real
    Hp = (phasors["H_phi"][where] * turn).real
    st, ct, sp_, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    E = np.stack([st * cp * Er + ct * cp * Et, st * sp_ * Er + ct * sp_ * Et, ct * Er - st * Et])
    H = np.stack([-sp_ * Hp, cp * Hp, np.zeros_like(Hp)])
    return np.stack([E, H])


def run_errors(exp, grid, phasors, dipole, sensors, times, traces, measured, smooth,
            quarter: int) -> dict:
    """Per estimator, component, zone and part: (mean squared error, mean squared truth).

    The record starts a quarter period (``quarter`` steps) before the table's window.
    ``real``: the estimate against ``Re{F e^{j omega t}}`` over the window. ``imag``: the
    experiment driven by ``Im{I0 e^{j omega t}}`` is this one a quarter period later, so
    its estimate at ``t`` is this run's estimate at ``t - T/4``, against
    ``Im{F e^{j omega t}}``. ``abs``: the magnitude formed from the two, against ``|F|``."""
    out = {}
    tree = spatial.cKDTree(grid.xyz[sensors])
    for zone, where in exp.plan.zones.items():
        _, nearest = tree.query(grid.xyz[where])
        turn = np.exp(1j * dipole.omega * times)[:, None]
        want = {"E_r": (phasors["E_r"][where] * turn).real,
                "E_theta": (phasors["E_theta"][where] * turn).real,
                "H_phi": (phasors["H_phi"][where] * turn).real}
        est = {}
        for name in (KF, SOURCE_ONLY, FIT, PLAIN, EULER):
            if not traces[name]:
                continue
            E = np.stack([tr["E"][0] for tr in traces[name]])[..., where]
            H = np.stack([tr["H"][0] for tr in traces[name]])[..., where]
            Es, Hs = fdtd.spherical(grid, E, where), fdtd.spherical(grid, H, where)
            est[name] = {"E_r": Es["r"], "E_theta": Es["theta"], "H_phi": Hs["phi"]}
        for name, data in (("measurement", measured), (RLS, smooth)):
            E, H = data[:, 0][..., nearest], data[:, 1][..., nearest]
            Es, Hs = fdtd.spherical(grid, E, where), fdtd.spherical(grid, H, where)
            est[name] = {"E_r": Es["r"], "E_theta": Es["theta"], "H_phi": Hs["phi"]}
        q = quarter
        for name, comps in est.items():
            for comp in COMPONENTS:
                x, w = comps[comp], want[comp]
                with np.errstate(all="ignore"):
                    pairs = {"real": (x[q:], w[q:]), "imag": (x[:-q], w[:-q]),
                             "abs": (np.hypot(x[q:], x[:-q]), np.hypot(w[q:], w[:-q]))}
                for part, (got, truth) in pairs.items():
                    with np.errstate(all="ignore"):
                        mse = float(np.mean((got - truth) ** 2))
                    out[(name, zone, comp, part)] = (mse if np.isfinite(mse) else np.inf,
                                                     float(np.mean(truth**2)))
    return out
