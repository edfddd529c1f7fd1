"""Behaviour cloning on the offline dataset: a small MLP from the observation vector to the
expert's speed over the next step (the forward part of the dataset's action, docs/dataset.md),
trained with numpy alone, as the sandbox has nothing else. Steering is left to the simulator's
lane controller (``LaneWithContinuousSpeed``): cloning the lateral part of the action too drove off
the road in every public scenario (errors compound where the replays never went).

Reads ``$ARENA_DATASET_DIR/transitions.npz`` and writes ``$ARENA_MODEL_DIR/weights.npz``. A
checkpoint after every epoch (``checkpoint.npz``: weights and optimiser state) lets a run that was
cut short resume where it stopped: the service saves ``ARENA_MODEL_DIR`` while training runs and a
training re-sent after its worker died starts with the last save in it (docs/dataset.md). The
checkpoint is written under another name and renamed, so a save never holds half of one.
"""

import itertools
import os
import time
from pathlib import Path

import numpy as np

HIDDEN = 64
EPOCHS = int(os.environ.get("BC_EPOCHS", "60"))
BATCH = 256
LEARNING_RATE = 1e-3
# The service trains each seed of a phase with its own ARENA_TRAIN_SEED (docs/training.md): the
# initial weights and the batch order come from it, so each seed trains another model.
SEED = int(os.environ.get("ARENA_TRAIN_SEED", "0"))
STEP_S = 0.1  # [s] the dataset's step: forward [m] per step -> speed [m/s]


def init(rng, n_in, n_out):
    sizes = [n_in, HIDDEN, HIDDEN, n_out]
    return {
        **{
            f"w{i}": rng.normal(0, np.sqrt(2 / a), (a, b))
            for i, (a, b) in enumerate(itertools.pairwise(sizes))
        },
        **{f"b{i}": np.zeros(b) for i, b in enumerate(sizes[1:])},
    }


def forward(params, x):
    h1 = np.maximum(x @ params["w0"] + params["b0"], 0)
    h2 = np.maximum(h1 @ params["w1"] + params["b1"], 0)
    return h2 @ params["w2"] + params["b2"], (x, h1, h2)


def gradients(params, cache, error):
    x, h1, h2 = cache
    n = len(x)
    grads = {"w2": h2.T @ error / n, "b2": error.mean(0)}
    d2 = (error @ params["w2"].T) * (h2 > 0)
    grads |= {"w1": h1.T @ d2 / n, "b1": d2.mean(0)}
    d1 = (d2 @ params["w1"].T) * (h1 > 0)
    grads |= {"w0": x.T @ d1 / n, "b0": d1.mean(0)}
    return grads


def save_atomically(path, **arrays):
    partial = path.with_name(f".{path.stem}.partial.npz")
    np.savez(partial, **arrays)
    os.replace(partial, path)


def main():
    data = np.load(Path(os.environ["ARENA_DATASET_DIR"]) / "transitions.npz")
    out = Path(os.environ["ARENA_MODEL_DIR"])
    x = data["observations"].astype(np.float64)
    y = data["actions"][:, :1].astype(np.float64) / STEP_S
    print(f"{len(x)} transitions, {int(data['episode'].max()) + 1} episodes", flush=True)
    x_mean, x_std = x.mean(0), x.std(0) + 1e-6
    y_mean, y_std = y.mean(0), y.std(0) + 1e-6
    xn, yn = (x - x_mean) / x_std, (y - y_mean) / y_std
    rng = np.random.default_rng(SEED)
    params = init(rng, x.shape[1], y.shape[1])
    moments = {k: (np.zeros_like(v), np.zeros_like(v)) for k, v in params.items()}
    first_epoch, step = 0, 0
    checkpoint = out / "checkpoint.npz"
    if checkpoint.exists():
        saved = np.load(checkpoint)
        params = {k: saved[k] for k in params}
        moments = {k: (saved[f"m_{k}"], saved[f"v_{k}"]) for k in params}
        first_epoch, step = int(saved["epoch"]) + 1, int(saved["step"])
        print(f"resuming after epoch {first_epoch}", flush=True)
    started = time.monotonic()
    for epoch in range(first_epoch, EPOCHS):
        order = rng.permutation(len(xn))
        for start in range(0, len(order), BATCH):
            batch = order[start : start + BATCH]
            prediction, cache = forward(params, xn[batch])
            grads = gradients(params, cache, prediction - yn[batch])
            step += 1
            for k, g in grads.items():
                m, v = moments[k]
                m[:] = 0.9 * m + 0.1 * g
                v[:] = 0.999 * v + 0.001 * g * g
                m_hat, v_hat = m / (1 - 0.9**step), v / (1 - 0.999**step)
                params[k] -= LEARNING_RATE * m_hat / (np.sqrt(v_hat) + 1e-8)
        loss = float(((forward(params, xn)[0] - yn) ** 2).mean())
        # One line per epoch, step,name,value: the service draws it as a curve while it trains.
        with (out / "training_metrics.csv").open("a") as metrics:
            metrics.write(f"{epoch + 1},loss,{loss:.6g}\n")
        print(
            f"epoch {epoch + 1}/{EPOCHS} loss {loss:.4f} ({time.monotonic() - started:.0f} s)",
            flush=True,
        )
        optimiser = {f"m_{k}": m for k, (m, _) in moments.items()}
        optimiser |= {f"v_{k}": v for k, (_, v) in moments.items()}
        save_atomically(checkpoint, epoch=epoch, step=step, **params, **optimiser)
    np.savez(out / "weights.npz", x_mean=x_mean, x_std=x_std, y_mean=y_mean, y_std=y_std, **params)
    checkpoint.unlink(missing_ok=True)
    print("saved weights.npz", flush=True)


if __name__ == "__main__":
    main()
