"""The paper's numbers (Table 1), for side-by-side comparison. Mean return over 100 episodes."""

TABLE1 = {
    "dqn": {"initial": 310.58, "under_attack": 108.22, "adversarial": 111.08, "after": 149.33},
    "ddpg": {"initial": 232.78, "under_attack": 45.44, "adversarial": 62.40, "after": 91.22},
}

ROWS = {
    "initial": "Initial Training",
    "under_attack": "Under Attack",
    "adversarial": "Adversarial Training",
    "after": "After Training (No Attack)",
}

ADV_STEPS = {"dqn": 5_000, "ddpg": 10_000}  # the paper's adversarial-training budgets
