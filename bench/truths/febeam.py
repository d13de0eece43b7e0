"""A non-uniform clamped–free Euler–Bernoulli strip by Hermite-cubic finite elements, and its
modal response to a distributed active bending moment.

Elements of length ``le`` carry their own bending stiffness EI_e and mass per length m_e
(a tapered strip, a thickness gradient, electrode layers).  Element matrices are the textbook
ones (Przemieniecki 1968): stiffness EI/le³·[[12, 6le, −12, 6le], …], consistent mass
m le/420·[[156, 22le, 54, −13le], …].  An active moment M_e, uniform over an element (the
charge-induced eigen-moment of a swelling bimorph), enters through ∫ M N'' dz = M·[0, −1, 0, +1] on
(w₁, θ₁, w₂, θ₂); a distributed couple μ per length, uniform over an element (tractions along
the two faces, opposite on each), through ∫ μ N' dz = μ·[−1, 0, +1, 0].
The root is clamped in deflection; its rotation is held by a spring k_θ (a real clamp is
not rigid; ``k_theta=None``: rigid).  Damping is Rayleigh, C = α M + β K (air drag and
Kelvin–Voigt material loss).

Checks against closed forms (uniform strip, rigid clamp): static tip deflection under a uniform
moment M L²/(2EI), under a uniform couple μ L³/(3EI); natural frequencies (β_i L)² sqrt(EI/m)/(2π L²) with β_1 L = 1.87510,
β_2 L = 4.69409 (e.g. Meirovitch, Elements of Vibration Analysis).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh


def element_matrices(EI: float, m: float, le: float) -> tuple[np.ndarray, np.ndarray]:
    k = EI / le ** 3 * np.array([[12, 6 * le, -12, 6 * le], [6 * le, 4 * le ** 2, -6 * le, 2 * le ** 2],
                                 [-12, -6 * le, 12, -6 * le], [6 * le, 2 * le ** 2, -6 * le, 4 * le ** 2]])
    mm = m * le / 420.0 * np.array([[156, 22 * le, 54, -13 * le], [22 * le, 4 * le ** 2, 13 * le, -3 * le ** 2],
                                    [54, 13 * le, 156, -22 * le], [-13 * le, -3 * le ** 2, -22 * le, 4 * le ** 2]])
    return k, mm


@dataclass
class Beam:
    """Assembled strip: ``K``, ``M`` on the free DOFs (θ₀, w₁, θ₁, …, w_n, θ_n), ``G`` the load
    of a unit active moment on each element (n_dof × n_el), ``Gc`` of a unit distributed couple,
    ``z`` element centres [m]."""

    K: np.ndarray
    M: np.ndarray
    G: np.ndarray
    Gc: np.ndarray
    z: np.ndarray
    le: float
    length: float

    @classmethod
    def build(cls, length: float, EI: np.ndarray, m: np.ndarray, k_theta: float | None = None) -> "Beam":
        EI, m = np.asarray(EI, dtype=float), np.asarray(m, dtype=float)
        n = EI.size
        le = length / n
        ndof = 2 * (n + 1)
        K = np.zeros((ndof, ndof))
        M = np.zeros((ndof, ndof))
        G = np.zeros((ndof, n))
        Gc = np.zeros((ndof, n))
        for e in range(n):
            k, mm = element_matrices(EI[e], m[e], le)
            sl = slice(2 * e, 2 * e + 4)
            K[sl, sl] += k
            M[sl, sl] += mm
            G[2 * e + 1, e] -= 1.0
            G[2 * e + 3, e] += 1.0
            Gc[2 * e, e] -= 1.0
            Gc[2 * e + 2, e] += 1.0
        if k_theta is not None:
            K[1, 1] += k_theta
            keep = np.arange(1, ndof)          # w0 = 0; θ0 on its spring
        else:
            keep = np.arange(2, ndof)          # rigid clamp
        z = (np.arange(n) + 0.5) * le
        return cls(K[np.ix_(keep, keep)], M[np.ix_(keep, keep)], G[keep], Gc[keep], z, le, length)

    def point_vector(self, zp: float) -> np.ndarray:
        """Row that gives the deflection at ``zp`` [m] from the DOFs (Hermite interpolation)."""
        n_el = self.z.size
        e = min(int(zp / self.le), n_el - 1)
        xi = zp / self.le - e
        le = self.le
        N = np.array([1 - 3 * xi ** 2 + 2 * xi ** 3, le * (xi - 2 * xi ** 2 + xi ** 3), 3 * xi ** 2 - 2 * xi ** 3,
                      le * (-xi ** 2 + xi ** 3)])
        full = np.zeros(2 * (n_el + 1))
        full[2 * e:2 * e + 4] = N
        off = 2 * (n_el + 1) - self.K.shape[0]
        return full[off:]

    def static(self, loads: np.ndarray, couple: bool = False) -> np.ndarray:
        """DOFs at rest under element active moments [N m] (``couple``: distributed couples [N m/m])."""
        return np.linalg.solve(self.K, (self.Gc if couple else self.G) @ loads)

    def modes(self) -> tuple[np.ndarray, np.ndarray]:
        """(ω_i [rad/s] ascending, mass-normalised mode shapes as columns)."""
        w2, phi = eigh(self.K, self.M)
        return np.sqrt(np.maximum(w2, 0.0)), phi


def modal_tip(omega: np.ndarray, tip_modal: np.ndarray, force: np.ndarray, s: np.ndarray, *, alpha: float,
              beta: float, stiffness_factor: np.ndarray | float = 1.0) -> np.ndarray:
    """Σ_i tip_i F_i(s) / (s² + (α + β ω_i²) s + ω_i² e(s)): the point response to modal forces
    ``force`` (n_modes × len(s)); ``stiffness_factor`` e(s) scales the polymer's stiffness
    (a frequency-dependent modulus relative to its reference; 1: elastic)."""
    w2 = omega[:, None] ** 2
    den = s[None, :] ** 2 + (alpha + beta * w2) * s[None, :] + w2 * stiffness_factor
    return np.sum(tip_modal[:, None] * force / den, axis=0)
