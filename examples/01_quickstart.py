"""Quickstart: declare a vibro-impact model, look at its averaged equations, get p(H), check it.
=============================================================================================

Run:  python examples/01_quickstart.py      (headless, a few seconds; exits 1 if a self-check fails)
"""

import sys

import matplotlib.pyplot as plt
import numpy as np
from scipy import integrate

from averaging import averaging_equations, stationary_density
from models import DuffingImpact, Elastic, Ma

# Example 1 of the paper (Fig. 2, delta = 1): x'' + c x' + a x + b x^3 = xi(t), |x| < delta, Ma restitution law
model = DuffingImpact(restitution=Ma(vc=0.4), a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0)
print(averaging_equations(model))  # Itô drift (Wong-Zakai), eq. 19 and the averaged coefficients

print(f"\nG(delta) = {model.barrier_energy:.4f}")
fig, ax = plt.subplots(figsize=(6, 4))
for method, style in (("paper", "-"), ("exact-two-impact", ":"), ("jump", "--")):
    sd = stationary_density(model, method, h_max=4.0, points=2000)
    ax.plot(sd.H, sd.p, style, label=f"{method}: E[H] = {sd.mean_energy:.3f}")
    print(f"{method:17s} E[H] = {sd.mean_energy:.4f}  P(H < G(delta)) = {sd.prob_below_barrier:.4f}  "
          f"E[x^2] = {sd.mean_x2:.4f}  impacts per unit time = {sd.impact_rate:.4f}")
df = sd.to_pandas()  # columns H, p
ax.axvline(model.barrier_energy, color="0.6", ls=":", label="G(delta): impacts begin")
ax.set(xlabel="H", ylabel="p(H)", xlim=(0, 2.5), title="Example 1 (Fig. 2, delta = 1, Ma V_C = 0.4): averaging")
ax.legend()
fig.tight_layout()

# Self-check: with elastic barriers the averaged density is exact, p(H) ~ T(H) exp(-c H / D).
elastic = model.with_restitution(Elastic())
sd = stationary_density(elastic, "paper", h_max=60.0, points=601)
a, b, c, D, delta = (elastic.params[k] for k in ("a", "b", "c", "D", "delta"))


def T(H):  # the period by plain quad, with x = A sin(t) to remove the turning-point singularity
    Amp = np.sqrt((np.sqrt(a * a + 4 * b * H) - a) / b)
    if Amp <= delta:  # 2H - 2G(A sin t) = cos(t)^2 (a A^2 + b A^4 (1 + sin(t)^2) / 2)
        f = lambda t: Amp / np.sqrt(a * Amp**2 + 0.5 * b * Amp**4 * (1 + np.sin(t) ** 2))  # noqa: E731
        return 4 * integrate.quad(f, 0, np.pi / 2, epsrel=1e-12)[0]
    return 4 * integrate.quad(lambda x: 1 / np.sqrt(2 * H - a * x * x - 0.5 * b * x**4), 0, delta, epsrel=1e-12)[0]


H = np.array([0.1, 0.4, 0.8, 2.0, 5.0])
ratio = sd.density(H) / np.array([T(h) * np.exp(-c * h / D) for h in H])
spread = np.ptp(ratio) / ratio.mean()
print(f"\nelastic check: p(H) / [T(H) exp(-cH/D)] varies by {spread:.2e} (should be ~0)")
if not spread < 1e-6:
    print("FAILED")
    sys.exit(1)
print("OK")
plt.show()  # nothing to show when headless (Agg); the documentation's gallery shows the figure
