"""The paper's numbers (Table 1), for side-by-side comparison. Mean return over 100 episodes."""

TABLE1 = {
    "dqn": {"initial": 310.58, "under_attack": 108.22, "adversarial": 111.08, "after": 149.33},
    "ddpg": {"initial": 232.78, "under_attack": 45.44, "adversarial": 62.40, "after": 91.22},
}

# The percentages as printed in the paper (some differ from return / 450, e.g. 108.22 -> 24.89 %).
TABLE1_PCT = {
    "dqn": {"initial": 69.01, "under_attack": 24.89, "adversarial": 22.78, "after": 33.18},
    "ddpg": {"initial": 51.73, "under_attack": 10.09, "adversarial": 13.87, "after": 20.27},
}

ROWS = {
    "initial": "Initial Training",
    "under_attack": "Under Attack",
    "adversarial": "Adversarial Training",
    "after": "After Training (No Attack)",
}

ADV_STEPS = {"dqn": 5_000, "ddpg": 10_000}  # the paper's adversarial-training budgets
