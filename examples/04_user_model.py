"""A user-defined model in a few lines: a hardening-softening spring between barriers, p(H) by averaging.
======================================================================================================

Run:  python examples/04_user_model.py      (headless, a few seconds; exits 1 if the self-check fails)
Or from the command line:  vibro pdf --model examples/04_user_model.py:HardeningSoftening --out p.csv
"""

import sys

import matplotlib.pyplot as plt
import numpy as np
from scipy import integrate

from averaging import averaging_equations, stationary_density
from models import Elastic, ImpactOscillator, Ma


class HardeningSoftening(ImpactOscillator):
    """x'' + c x' + x + k3 x^3 - k5 x^5 = xi(t), |x| < delta."""

    name = "hardening-softening"

    def __init__(self, restitution=None, **params):
        super().__init__(restoring="x + k3*x**3 - k5*x**5", damping="c*y", noise=(1,), intensity="D",
                         parameters={"k3": 0.5, "k5": 0.05, "c": 0.03, "D": 0.04, "delta": 1.5, **params},
                         restitution=restitution or Ma(vc=0.3))


def main() -> int:
    model = HardeningSoftening()
    print(averaging_equations(model))
    fig, ax = plt.subplots(figsize=(6, 4))
    for method, style in (("paper", "-"), ("jump", "--")):
        sd = stationary_density(model, method, h_max=5.0, points=1000)
        print(f"{method:6s} E[H] = {sd.mean_energy:.4f}  P(no impact) = {sd.prob_below_barrier:.4f}")
        ax.plot(sd.H, sd.p, style, label=f"{method}: E[H] = {sd.mean_energy:.3f}")
    ax.axvline(model.barrier_energy, color="0.6", ls=":", label="G(delta)")
    ax.set(xlabel="H", ylabel="p(H)", title="x'' + c x' + x + k3 x^3 - k5 x^5 = xi, |x| < 1.5, Ma V_C = 0.3")
    ax.legend()
    fig.tight_layout()

    # Self-check (elastic barriers are exact): p(x) ~ exp(-c G(x) / D) on |x| < delta, computed here by plain quad.
    el = model.with_restitution(Elastic())
    sd = stationary_density(el, "paper", h_max=60.0, points=601)
    c, D, delta = el.params["c"], el.params["D"], el.params["delta"]

    def G(x):
        return x * x / 2 + 0.5 * x**4 / 4 - 0.05 * x**6 / 6

    Z = integrate.quad(lambda x: np.exp(-c * G(x) / D), -delta, delta, epsrel=1e-12)[0]
    x = np.array([-1.2, 0.0, 0.7, 1.4])
    err = np.max(np.abs(sd.marginal_x(x) / (np.exp(-c * G(x) / D) / Z) - 1))
    print(f"elastic check: max relative error of p(x) = {err:.2e}")
    if not err < 1e-6:
        print("FAILED")
        return 1
    print("OK")
    plt.show()  # nothing to show when headless (Agg); the documentation's gallery shows the figure
    return 0


if __name__ == "__main__":
    sys.exit(main())
