"""Running jobs anywhere: units on this process, a local process pool or Ray core, resumable.

`run.run_units` is the one entry point (training campaigns, PSRO and evaluation tables all use
it); `local` and `ray` are its back ends and `units` what a unit is, how it is keyed and how its
finished part file is written and read back.
"""
