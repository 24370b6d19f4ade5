"""The seed ranges, in one place: training, tuning and evaluation never share a seed; and the most
episodes one run may ask for (checked by the CLI and the API alike before anything is allocated)."""

TUNING_SEED = 50_000   # first seed for tuning, sweeps, figures and benchmarks
EVAL_SEED = 100_000    # first evaluation seed; training uses seeds below 50,000
MAX_EPISODES = 1_000_000  # a million episodes is days of CPU
