"""Power spectral density of the displacement from the phase-plane generator's resolvent.
======================================================================================

S(omega) is one-sided, normalised so that its integral over (0, inf) is the variance: one complex sparse solve of
(i omega M + A) per frequency, A the phase-plane solver's operator with its impact boundary. The free linear
oscillator checks it against ``|H(omega)|^2 2D/pi``; Example 1 (Duffing with walls at +-1, Ma V_C = 0.4) then gives its
peak frequency, half-power bandwidth and the variance check.

Run:  python examples/12_spectrum.py [--quick]   (headless; exits 1 if a check fails)
"""

import sys

import numpy as np

import vibro
from models import DuffingImpact, ImpactOscillator, Ma


def main(quick: bool) -> int:
    grid = (40, 48) if quick else (80, 96)
    c, D = 0.2, 0.05
    lin = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    s = vibro.spectrum(lin, "x", omega_max=4.0, points=60 if quick else 150, refine=40, grid=grid, h_max=3.0)
    exact = (2 * D / np.pi) / ((1 - s.omega**2) ** 2 + c**2 * s.omega**2)
    l1 = np.trapezoid(np.abs(s.S - exact), s.omega) / np.trapezoid(exact, s.omega)
    print(f"linear oscillator: {s}")
    print(f"  L1 distance to the exact PSD {l1:.4f}; exact peak {np.sqrt(1 - c * c / 2):.5f}, variance {D / c:.5f}")
    ok = l1 < 0.05 and abs(s.variance_check - 1) < 0.01
    duff = vibro.spectrum(DuffingImpact(restitution=Ma(vc=0.4)), "x", omega_max=3.0,
                          points=60 if quick else 150, refine=40 if quick else 100, grid=grid)
    print(f"Example 1: {duff}")
    print(f"  peak omega {duff.peak_omega:.5f}, half-power bandwidth {duff.bandwidth:.4f}, "
          f"int_0^3 S = {duff.integral:.6f} of Var = {duff.variance:.6f}")
    ok &= abs(duff.variance_check - 1) < 0.02
    plot(s, exact, duff)
    print("OK" if ok else "FAILED")
    return 0 if ok else 1


def plot(s, exact, duff) -> None:
    """The linear oscillator's spectrum against its closed form, and Example 1's."""
    import tempfile
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    a.plot(s.omega, exact, "k-", label="exact |H|^2 2D/pi")
    a.plot(s.omega, s.S, "o", ms=3, label="fpk resolvent")
    a.set(xlabel="omega", ylabel="S(omega)", title="linear oscillator, c = 0.2", yscale="log")
    a.legend()
    b.plot(duff.omega, duff.S, "k-")
    b.axvline(duff.peak_omega, color="0.6", ls=":", label=f"peak {duff.peak_omega:.3f}")
    b.set(xlabel="omega", ylabel="S(omega)", title="Example 1 (walls at +-1, Ma V_C = 0.4)")
    b.legend()
    fig.tight_layout()
    out = Path(tempfile.mkdtemp(prefix="vibro-example-12-")) / "12_spectrum.png"
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")


if __name__ == "__main__":
    sys.exit(main("--quick" in sys.argv))
