"""What users run: data preparation, training, evaluation, export, closed-loop simulation, sweeps, review."""
