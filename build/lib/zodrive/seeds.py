"""The seed ranges, in one place: training, tuning and evaluation never share a seed."""

TUNING_SEED = 50_000   # first seed for tuning, sweeps, figures and benchmarks
EVAL_SEED = 100_000    # first evaluation seed; training uses seeds below 50,000
