"""Playing a robustness table: protagonists × adversary columns × seeds, into a `PayoffTable`."""
