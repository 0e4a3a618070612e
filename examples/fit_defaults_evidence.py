"""Evidence for the SH-fit defaults (rcond, horizon weight) and the basis choice.

Run:  python examples/fit_defaults_evidence.py

Simulates the dynamic-BRDF paper's witness-screen protocol on an analytic grooved-metal
truth (brdfmodels.validation), fits with each setting, and prints the held-out
prediction error next to the training residual; then the leave-one-test-out basis
choice and the paper's protocol with the chosen defaults. docs/fit-defaults.md records
one run of it.
"""

from brdfmodels import validation as v
from brdfmodels.accuracy import format_table

if __name__ == "__main__":
    print(format_table(v.select_fit_defaults(), "single-state fits: rcond x horizon weight (held-out = 10, 30 deg horizontal, 40 deg vertical)"))
    print()
    fit = v.protocol_samples(times_s=(0.0,))
    best, table = v.choose_sh_basis(fit)
    print(format_table(table, "leave-one-test-out over basis orders and fan-out"))
    print(f"chosen: {best}")
    print()
    res = v.run_protocol()
    print(format_table(res.per_test, "paper protocol, dynamic fit (state = time), held-out tests"))
    print(res.interpolation)
