"""A long best response (a searched attack's candidate) goes on from its last save after a kill.

Where the runner keeps part files it gives each unit a scratch folder
(`advgame.core.scratch`); an on-policy best response saves its learner there at rollout
boundaries. Checked: the saves change nothing (the same weights as one uninterrupted
``learn``, for an adversary and for a normalized protagonist trained in chunks, and for an LSTM
adversary), a job stopped half way trains only the steps it had left when run again, and the
folder is gone once the unit's part file is written.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest
import torch

from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.core.progress import listening
from advgame.core.scratch import scratch_folder
from advgame.runner.run import JobFailedError, run_units
from advgame.training import best_response
from advgame.training.best_response import BestResponseJob, MixtureSpec, train_best_response
from advgame.workflows.suite import observation_agent

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SCENARIO, PRESET = "InvertedPendulum-v5", "obs-normalized-0.1"
SMALL = {"n_steps": 64, "batch_size": 32, "n_epochs": 2, "learning_rate": 1e-3, "lr_decay": True}


def _job(pendulum_ppo: Path, *, algo: str = "ppo", victim: bool = False) -> BestResponseJob:
    """An adversary against the pendulum PPO, or (`victim`) a protagonist against a fixed one."""
    agent = observation_agent(SCENARIO, PRESET)
    spec = SB3Checkpoint(str(pendulum_ppo), "ppo")
    if victim:  # the learner is the attacked protagonist: trained in chunks behind its normalizer
        from advgame.adversaries.noise import RandomAdversary

        opponents = {agent: MixtureSpec((RandomAdversary(),), (1.0,))}
        agent = "protagonist"
    else:
        opponents = {"protagonist": MixtureSpec((spec,), (1.0,))}
    hparams = dict(SMALL) if algo == "ppo" else {**SMALL, "net_arch": (16,)}
    return BestResponseJob(
        name="br", scenario=SCENARIO, make_kwargs={"preset": PRESET}, agent=agent, algo=algo,
        hparams=hparams, opponents=opponents, steps=64 * 20 + 17, seed=3,
    )  # fmt: skip


def _weights(result: dict[str, Any]) -> dict[str, torch.Tensor]:
    import zipfile

    with zipfile.ZipFile(io.BytesIO(result["files"][result["model"]])) as z:
        return torch.load(io.BytesIO(z.read("policy.pth")), map_location="cpu")


@pytest.mark.parametrize(
    ("algo", "victim"), [("ppo", False), ("ppo", True), ("recurrent-ppo", False)]
)
def test_saving_along_the_way_changes_no_weight(
    pendulum_ppo: Path, tmp_path: Path, algo: str, victim: bool
) -> None:
    job = _job(pendulum_ppo, algo=algo, victim=victim)
    plain = train_best_response(job)
    saves: list[int] = []
    real = best_response._save

    def counted(side: Any, folder: Path, done: int) -> None:
        saves.append(done)
        real(side, folder, done)

    best_response._save = counted  # type: ignore[assignment]
    reports: list[int] = []
    try:
        with scratch_folder(tmp_path / "scratch"), listening(reports.append):
            saved = train_best_response(job)
    finally:
        best_response._save = real  # type: ignore[assignment]
    assert len(saves) >= 10 and saves == sorted(saves) and saves[-1] < job.steps
    # each piece is reported as it is trained (a bar counting steps moves inside the job)
    assert sum(reports) == job.steps and len(reports) == len(saves) + 1
    a, b = _weights(plain), _weights(saved)
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)


class _Stop(RuntimeError):
    """The 'kill' of the test: raised from inside training."""


@pytest.mark.parametrize("algo", ["ppo", "recurrent-ppo"])
def test_a_stopped_job_goes_on_from_its_last_save_and_its_folder_goes_with_its_part(
    pendulum_ppo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, algo: str
) -> None:
    from advgame.agents.common.side import Side

    job, parts = _job(pendulum_ppo, algo=algo), tmp_path / "parts"
    learned: list[int] = []
    real_learn = Side.learn

    def learn(self: Side, steps: int, stats: Any = None) -> None:
        if stop_after is not None and len(learned) == stop_after:
            raise _Stop("killed")
        learned.append(steps)
        real_learn(self, steps, stats)

    monkeypatch.setattr(Side, "learn", learn)
    stop_after: int | None = 7
    with pytest.raises(JobFailedError, match="killed"):
        run_units(train_best_response, [job], parts_dir=parts, max_retries=0, scratch=True)
    (folder,) = parts.glob("*.scratch")
    assert (folder / "state.json").is_file()
    first = sum(learned)
    assert first == 7 * 64  # seven pieces of one rollout each were trained before the stop
    learned.clear()
    stop_after = None
    (record,) = run_units(train_best_response, [job], parts_dir=parts, max_retries=0, scratch=True)
    assert sum(learned) == job.steps - first  # from the save after piece seven
    assert not list(parts.glob("*.scratch"))  # the part file holds the result now
    (parts / f"{record.key}.scratch" / "a").mkdir(parents=True)  # a kill right after the part
    run_units(train_best_response, [job], parts_dir=parts, max_retries=0, scratch=True)
    assert not list(parts.glob("*.scratch"))  # read back, its stale folder removed
    assert (parts / f"{record.key}.pkl").is_file()
    from advgame.agents.common.checkpoint import _algo_class

    # without scratch=True (PSRO: a resumed run is the uninterrupted one) no folder is given
    learned.clear()
    again = run_units(train_best_response, [job], parts_dir=tmp_path / "plain", max_retries=0)
    assert sum(learned) == job.steps and not list((tmp_path / "plain").glob("*.scratch"))
    assert len(learned) == 1  # one learn call: no saves
    assert again[0].key == record.key
    zipped = io.BytesIO(record.value["files"][record.value["model"]])
    assert _algo_class(algo).load(zipped, device="cpu").num_timesteps >= job.steps


def test_a_save_that_no_longer_loads_is_dropped_and_the_job_starts_over(
    pendulum_ppo: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    job, folder = _job(pendulum_ppo), tmp_path / "scratch"
    (folder / "a").mkdir(parents=True)  # the state names a slot whose files are gone
    (folder / "state.json").write_text('{"slot": "a", "steps": 640}\n')
    reports: list[int] = []
    with scratch_folder(folder), listening(reports.append):
        result = train_best_response(job)
    assert sum(reports) == job.steps  # every step trained here, none taken from the save
    assert "does not load" in caplog.text
    assert result["model"]
