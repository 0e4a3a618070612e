"""Error against run time for the BRDF library's accuracy knobs.

Run:  python examples/accuracy_tables.py

1. DHR quadrature tolerance for a sharp (2 deg) specular SH lobe: value, true error
   against a tight reference, the quadrature's own error estimate, evaluations, time.
2. Heating/oxidation ODE tolerance for a stainless plate heated through melting: max
   error in temperature and oxide extinction against a tight reference, and time.
"""

from brdfmodels.accuracy import dhr_error_table, format_table, heating_tolerance_table

if __name__ == "__main__":
    print(format_table(dhr_error_table(), "DHR quadrature (sharp 2-deg SH lobe, normal incidence)"))
    print()
    print(format_table(heating_tolerance_table(), "Thin-plate heating + oxidation (stainless, 2e7 W/m^2, 3 s)"))
