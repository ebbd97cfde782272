"""The TE core: units, sums of sinusoids, exact extrema, metric objects, result codes, study-file tables. Knows no drive."""
