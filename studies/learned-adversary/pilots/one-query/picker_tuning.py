"""The tuning probe behind `zodrive picker-train`'s defaults (issue 23; kept as run, not a product command):
vertex hold whose fresh vertex is the best of --k random ones by a classifier fitted offline (training
seeds 0-19, 1000-1019, ... one block per round) to "the victim takes FASTER on this perturbed observation",
--per random vertices queried per state met; compared on tuning seeds 900000-900029 with plain vertex hold.
--save / --load keep the classifier; with --load and --seed0 100000 --episodes 100 it runs on the evaluation
seeds and pairs with the committed random-search cell of dqn-close at eps 0.02. Commands and printed output:
results/learned-adversary/pilots/one-query/tuning.txt. The product (`zodrive.training.picker`, `zodrive.attacks.picker`) is this, cleaned up.
"""
import argparse, os, sys, numpy as np, torch
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import FASTER, drive, setup, show, vertex_hold
p = argparse.ArgumentParser()
p.add_argument("model"); p.add_argument("eps", type=float)
p.add_argument("--train", type=int, default=20); p.add_argument("--per", type=int, default=512)
p.add_argument("--k", type=int, default=64); p.add_argument("--episodes", type=int, default=30)
p.add_argument("--rounds", type=int, default=2); p.add_argument("--save"); p.add_argument("--load")
p.add_argument("--switch", type=float, default=0.0); p.add_argument("--epochs", type=int, default=3); p.add_argument("--width", type=int, default=256); p.add_argument("--seed0", type=int, default=900000)
a = p.parse_args()
torch.manual_seed(0)
_, victim, env, threat = setup(a.model, a.eps)
shape = env.observation_space.shape; mask = threat.mask(shape)
rng = np.random.default_rng(0)
def verts(n): return a.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=(n, *shape)) * mask
net = torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(int(np.prod(shape)), a.width), torch.nn.ReLU(),
                          torch.nn.Linear(a.width, a.width), torch.nn.ReLU(), torch.nn.Linear(a.width, 1))
X, Y = [], []
def picker(x, memory):
    stale = False
    if a.switch > 0 and memory.get("held") is not None and not memory["missed"]:
        with torch.no_grad():
            stale = torch.sigmoid(net(torch.from_numpy(threat.project(x + memory["held"], x)))).item() < a.switch
    if memory.get("held") is None or memory["missed"] or stale:
        cand = threat.project(x + verts(a.k), np.repeat(x, a.k, axis=0))
        with torch.no_grad():
            s = net(torch.from_numpy(cand)).squeeze(1).numpy()
        memory["held"] = cand[int(s.argmax())] - x[0]
    return threat.project(x + memory["held"], x)
collect = vertex_hold(threat, shape, rng)
if a.load: net.load_state_dict(torch.load(a.load)); a.rounds = 0
for r in range(a.rounds):
    states = []
    res = drive(env, victim, 1000 * r, a.train, collect, states=states)
    for s in states:
        fed = threat.project(s[None] + verts(a.per), np.repeat(s[None], a.per, axis=0))
        X.append(fed); Y.append(victim.query(fed).argmax(1) == FASTER)
    x_all = torch.from_numpy(np.concatenate(X)); y_all = torch.from_numpy(np.concatenate(Y).astype(np.float32))
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    for ep in range(a.epochs):
        perm = torch.randperm(len(x_all))
        for i in range(0, len(perm), 4096):
            b = perm[i:i + 4096]
            loss = torch.nn.functional.binary_cross_entropy_with_logits(net(x_all[b]).squeeze(1), y_all[b])
            opt.zero_grad(); loss.backward(); opt.step()
    with torch.no_grad():
        acc = ((net(x_all[:200000]).squeeze(1) > 0) == (y_all[:200000] > 0.5)).float().mean().item()
    print(f"round {r}: collected under {'hold' if r == 0 else 'picker'} return {res['return']:.2f}, {len(x_all)} samples, "
          f"base rate {y_all.mean():.1%}, train acc {acc:.1%}", flush=True)
    collect = picker
if a.save: torch.save(net.state_dict(), a.save)
if not a.load: show("vertex hold", drive(env, victim, 900000, a.episodes, vertex_hold(threat, shape, np.random.default_rng(0))))
if not a.load: show(f"hold, fresh vertex = best of {a.k} by the classifier, switch {a.switch}", drive(env, victim, a.seed0, a.episodes, picker))
if a.load:
    import json
    r = drive(env, victim, a.seed0, a.episodes, picker); show("picker", r)
    json.dump({str(a.seed0 + i): v for i, v in enumerate(r["returns"])}, open(os.devnull, "w"))
    from zodrive.evaluation import store  # the cell's folder, or its line in results/close-rules/attacked.jsonl.gz
    rs = {str(row["seed"]): row["return"] for row in store.episodes("results/close-rules/attacked/random-search-eps0.02")}
    from zodrive.evaluation.stats import paired_difference_ci
    seeds = sorted(set(rs) & {str(a.seed0 + i) for i in range(a.episodes)})
    if seeds:
        print("paired picker - random search", paired_difference_ci([r["returns"][int(s) - a.seed0] for s in seeds], [rs[s] for s in seeds]), len(seeds))
