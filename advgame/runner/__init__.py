"""Running jobs anywhere: units on this process, a local process pool or Ray core, resumable.

`run.run_units` is the one entry point (training campaigns, PSRO and evaluation tables all use
it); `local` and `ray` are its back ends, `units` what a unit is and how its finished part file
is written and read, and `parts` how a unit's part file is named (from any folder).
"""
