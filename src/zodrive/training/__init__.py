"""Training: policies from recipes, fine-tuned or made robust (adversarial training, SA
regularizers, robust distillation), and the attackers that are fitted (learned adversary, picker)."""
