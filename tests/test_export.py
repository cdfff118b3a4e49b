"""ONNX export (train.export): parity with torch on recorded observations, the metadata contract, the exported file
in the evaluation harness, the released demo's contract (its three files, input names and shapes), and each bad
input as a one-line error that leaves nothing behind."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import onnx
import pytest
import torch
from mocap_paths import expect_input_error

from pipeline.robot import G1_JOINT_NAMES, actuator_profile
from pipeline.stage.paths import stage_dir
from pipeline.terms import layout as L
from train.actors import PolicyActor
from train.bc import BCConfig, train_bc
from train.envs.cpu.env import EnvConfig, InteractionEnv
from train.evaluation.table2 import EvalConfig, evaluate
from train.export.demo import DEMO_FILES, DEMO_INPUTS, demo_inputs, export_demo, viewer_state
from train.export.demo_loop import DemoLoop, DemoLoopConfig, DemoPolicy, run_demo_episode
from train.export.metadata import METADATA_KEY, sha256
from train.export.onnx_policy import export_onnx
from train.export.parity import parity, recorded_windows
from train.export.runtime import OnnxPolicy, read_metadata
from train.policy import PolicyConfig, load_policy
from train.vae import VAEConfig


def OnnxSession(path):
    import onnxruntime as ort

    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


@pytest.fixture(scope="module")
def exported(bc_corpus, tmp_path_factory):
    """``(episodes, checkpoint, onnx path)``: the tiny BC policy of ``bc_corpus`` exported once."""
    episodes, checkpoint = bc_corpus
    out = tmp_path_factory.mktemp("export") / "policy.onnx"
    report = export_onnx(checkpoint, out)
    assert report.path == out and out.stat().st_size == report.bytes and report.check_max_abs <= 1e-5
    return episodes, checkpoint, out


def test_onnx_acts_as_torch_on_recorded_observations(exported):
    episodes, checkpoint, out = exported
    policy = load_policy(checkpoint)
    windows = recorded_windows(policy, episodes[:2], steps=40)
    assert windows[0].shape[1:] == (policy.layout.history, L.PROPRIO_DIM) and len(windows[0]) >= 40
    assert np.ptp(windows[0][:, -1, :29], axis=0).max() > 1e-3  # the robot moved: not one observation repeated
    result = parity(policy, out, windows)
    assert result["windows"] == len(windows[0]) and result["max_abs"] <= 1e-5, result
    one = OnnxPolicy(out).act(*(torch.from_numpy(w[:1]) for w in windows))  # batch 1: the axis is dynamic
    assert one.shape == (1, L.ACTION_DIM)


def test_the_metadata_says_how_to_run_the_file(exported):
    _, checkpoint, out = exported
    meta = read_metadata(out)
    policy = load_policy(checkpoint)
    profile = actuator_profile(policy.layout.actuator_profile)
    assert meta["joint_names"] == list(G1_JOINT_NAMES) and meta["checkpoint"]["sha256"] == sha256(checkpoint)
    assert np.allclose(meta["actuator"]["kp"], profile.kp) and np.allclose(meta["actuator"]["kd"], profile.kd)
    assert np.allclose(meta["actuator"]["default_joint_pos"], profile.default_joint_pos)
    assert meta["control"] == {"fps": 50, "dt_s": 0.02, "physics_timestep_s": 0.005, "substeps": 4}
    inputs = meta["observation"]["inputs"]
    assert inputs["proprio"]["names"] == list(L.PROPRIO_NAMES) and inputs["df"]["shape"][-1] == policy.layout.df_dim
    assert meta["policy"]["layout"] == policy.layout.to_dict()
    model = onnx.load(str(out))
    graph_inputs = {
        i.name: [d.dim_param or d.dim_value for d in i.type.tensor_type.shape.dim] for i in model.graph.input
    }
    hist = policy.layout.history
    assert graph_inputs == {
        "proprio": ["batch", hist, 93],
        "root_command": ["batch", hist, 12],
        "df": ["batch", hist, policy.layout.df_dim],
    }
    assert [o.name for o in model.graph.output] == ["joint_targets"]
    props = {p.key: p.value for p in model.metadata_props}
    assert json.loads(props[METADATA_KEY]) == meta  # one JSON contract, and mjlab's flat keys beside it
    assert props["joint_names"].split(",") == list(G1_JOINT_NAMES)
    assert np.allclose([float(v) for v in props["joint_stiffness"].split(",")], profile.kp, rtol=0, atol=0)
    assert "action_scale" not in props  # absolute targets: mjlab's default + scale * a would add the pose twice


def test_the_exported_file_runs_in_the_evaluation_harness(exported):
    episodes, _, out = exported
    cfg = EvalConfig(seeds=(0,), episodes=1, envs=1, tasks=("PickUp",), scales=(1.0,))
    cell = evaluate(PolicyActor(OnnxPolicy(out)), episodes, cfg, "onnx")["cells"]["PickUp@1"]
    assert cell["episodes"] == 1 and 0.0 <= cell["mean"] <= 1.0


def test_bad_inputs_are_one_line_errors_and_leave_nothing(exported, tmp_path):
    _, checkpoint, out = exported
    ckpt = torch.load(checkpoint, weights_only=True)
    torch.save({"weights": torch.zeros(3)}, tmp_path / "other.pt")
    expect_input_error(lambda: export_onnx(tmp_path / "other.pt"), tmp_path, file=tmp_path / "other.pt", field="format")

    name = next(iter(ckpt["backbone"]))
    bad = {**ckpt, "backbone": {**ckpt["backbone"], name: ckpt["backbone"][name].clone().fill_(float("nan"))}}
    torch.save(bad, tmp_path / "nan.pt")
    expect_input_error(
        lambda: export_onnx(tmp_path / "nan.pt"), tmp_path, file=tmp_path / "nan.pt", field=f"backbone.{name}"
    )

    (tmp_path / "policy.onnx").write_bytes(b"an earlier export")
    torch.save(ckpt, tmp_path / "policy.pt")
    expect_input_error(
        lambda: export_onnx(tmp_path / "policy.pt"), tmp_path, file=tmp_path / "policy.onnx", field="output"
    )
    assert export_onnx(tmp_path / "policy.pt", overwrite=True).bytes == (tmp_path / "policy.onnx").stat().st_size

    plain = tmp_path / "plain.onnx"
    model = onnx.load(str(out))
    del model.metadata_props[:]
    onnx.save(model, str(plain))
    expect_input_error(lambda: OnnxPolicy(plain), tmp_path, file=plain, field=f"metadata_props.{METADATA_KEY}")
    from lessmimic.cli import main

    assert main(["eval", "--name", "train", "--policy", str(plain), "--out", str(tmp_path / "eval")]) == 2
    want = {"actuator_profile": "lessmimic_demo"}
    expect_input_error(lambda: OnnxPolicy(out, want), out.parent, file=out, field="layout.actuator_profile")


@pytest.fixture(scope="module")
def demo_policy(bc_corpus, tmp_path_factory):
    """``(episodes, checkpoint, same policy under mjlab's gains)``: a tiny policy of the demo contract on the fixture
    corpus, its checkpoint relabelled to the demo's gains (the graphs do not depend on them; the fixture corpus is
    physicalized under mjlab's, so its episodes are relabelled alike)."""
    episodes, _ = bc_corpus
    run = tmp_path_factory.mktemp("demo_run")
    features = stage_dir("train", "features")
    train_bc(
        features, run, BCConfig(steps=20, log_every=10), PolicyConfig(), VAEConfig(), 20, contract="lessmimic_demo"
    )
    ckpt = torch.load(run / "policy.pt", weights_only=True)
    torch.save(ckpt, run / "policy_mjlab.pt")
    ckpt["layout"]["actuator_profile"] = "lessmimic_demo"
    torch.save(ckpt, run / "policy.pt")
    return [replace(e, profile="lessmimic_demo") for e in episodes], run / "policy.pt", run / "policy_mjlab.pt"


def test_the_demo_export_has_the_viewers_inputs_and_acts_as_torch(demo_policy, tmp_path):
    episodes, checkpoint, _ = demo_policy
    out = export_demo(checkpoint, tmp_path / "demo")
    assert sorted(p.name for p in out.iterdir()) == sorted(DEMO_FILES)
    shapes = {}
    for name in ("latent_encoder.onnx", "policy.onnx"):
        model = onnx.load(str(out / name))
        for i in [*model.graph.input, *model.graph.output]:
            shapes[i.name] = [d.dim_param or d.dim_value for d in i.type.tensor_type.shape.dim]
    assert shapes == {
        "state": ["batch", 28],
        "latent": ["batch", 64],
        **{k: ["batch", n] for k, n in DEMO_INPUTS.items()},
        "action": ["batch", 29],
    }
    assert DEMO_INPUTS == {"proprio": 465, "movement_goal": 12, "task_condition": 2, "interaction_field": 320}
    config = json.loads((out / "interaction_policy.json").read_text())
    assert config["stiffness"] == actuator_profile("lessmimic_demo").kp.tolist() and config["history_length"] == 5
    assert (
        config["sdf"]["query_body_names"] == list(L.DEMO_LINKS) and config["policy_joint_names"][0] == G1_JOINT_NAMES[0]
    )
    policy = load_policy(checkpoint)
    windows = recorded_windows(policy, episodes[:2], steps=30)
    assert windows[1].shape[-1] == 14 and windows[2].shape[-1] == 28
    with torch.no_grad():
        want = policy.act(*(torch.from_numpy(w) for w in windows)).numpy()
    feeds = demo_inputs(policy, *windows)
    latents = feeds["interaction_field"].reshape(len(want), 5, 64)
    np.testing.assert_allclose(np.linalg.norm(latents, axis=-1), 1.0, atol=1e-5)  # unit latents, newest first
    np.testing.assert_allclose(feeds["proprio"][:, :29], windows[0][:, -1, :29], atol=0)  # newest joint angles first
    state = viewer_state(windows[2][:, -1])  # the viewer's order: 7 distances, then 7 x 3 gradients
    np.testing.assert_array_equal(state[:, :7], windows[2][:, -1, ::4])
    raw = OnnxSession(out / "latent_encoder.onnx").run(["latent"], {"state": state})[0]
    unit = raw / (np.linalg.norm(raw, axis=-1, keepdims=True) + 1e-8)
    np.testing.assert_allclose(unit, latents[:, 0], atol=1e-5)  # the encoder file gives the policy's latents
    got = OnnxSession(out / "policy.onnx").run(["action"], feeds)[0]
    assert np.abs(got - want).max() <= 1e-5
    pickup = next(e for e in episodes if e.task == "PickUp")
    for cfg in (DemoLoopConfig(), DemoLoopConfig(distance="exact")):  # the viewer's loop, its grids or our field
        run = run_demo_episode(out, pickup, cfg, max_steps=5)
        assert run["steps"] == 5 and run["episode_profile"] == "lessmimic_demo"
    loop = DemoLoop(DemoPolicy(out), pickup)  # its grids read our exact field's features where both are defined
    env = InteractionEnv(EnvConfig.for_policy(load_policy(checkpoint).layout))
    env.reset([(pickup, 1.0)])
    np.testing.assert_allclose(loop.interaction_state(), viewer_state(env.observe().df[0]), atol=0.05)


def test_the_demo_export_refuses_other_contracts_gains_and_existing_files(bc_corpus, demo_policy, tmp_path):
    _, paper_policy = bc_corpus
    _, checkpoint, mjlab_gains = demo_policy
    out = tmp_path / "demo"
    expect_input_error(lambda: export_demo(paper_policy, out), tmp_path, file=paper_policy, field="layout.contract")
    expect_input_error(
        lambda: export_demo(mjlab_gains, out), tmp_path, file=mjlab_gains, field="layout.actuator_profile"
    )
    export_demo(checkpoint, out)
    expect_input_error(lambda: export_demo(checkpoint, out), tmp_path, file=out / DEMO_FILES[0], field="output")
    assert export_demo(checkpoint, out, overwrite=True) == out


def _site(tmp_path):
    """A viewer site laid out as the released one: the page in ``static/humanoid-policy-viewer/`` with its scene and
    its released JSON, its SDF grids two folders up in ``lessmimic-live-demo-assets/``: ``(root, page folder)``."""
    root = tmp_path / "lessmimic.github.io"
    site = root / "static" / "humanoid-policy-viewer"
    for path, text in (
        (site / "index.html", "<html></html>"),
        (site / "examples/scenes/g1/g1_interaction.xml", "<mujoco/>"),
        (site / "examples/checkpoints/g1/interaction_policy.json", "{}"),
        *((root / f"lessmimic-live-demo-assets/{k}_sdf.json", "{}") for k in ("box", "chair", "crate")),
    ):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root, site


def test_the_demo_export_lands_where_the_viewer_fetches_it(demo_policy, tmp_path, capsys):
    """``--viewer-site``: every path the JSON names, resolved against the viewer's page as a browser resolves a
    fetch (the site served from its root), is a file there, the ONNX ones ours; a bare name (the old JSON's) would
    not be; a folder without the page, ``--out`` with a site and the released JSON without ``--overwrite`` are
    one-line errors."""
    from urllib.parse import urljoin, urlparse

    from lessmimic.cli import main
    from train.export.viewer_site import VIEWER_URLS, fetched_files

    _, checkpoint, _ = demo_policy
    root, site = _site(tmp_path)
    released = site / "examples/checkpoints/g1/interaction_policy.json"
    expect_input_error(lambda: export_demo(checkpoint, viewer_site=site), tmp_path, file=released, field="output")
    expect_input_error(lambda: export_demo(checkpoint, viewer_site=root), tmp_path, file=root, field="viewer_site")
    expect_input_error(lambda: export_demo(checkpoint, tmp_path / "x", viewer_site=site), tmp_path, file=site,
                       field="viewer_site")  # fmt: skip
    argv = ["export", "--policy", str(checkpoint), "--format", "lessmimic-demo", "--viewer-site", str(site)]
    assert main([*argv, "--overwrite"]) == 0
    printed = capsys.readouterr().out
    assert "MISSING" not in printed and printed.count("(present)") == 6

    page = "https://lessmimic.github.io/static/humanoid-policy-viewer/index.html"

    def served(url: str):  # the file a fetch of url from the page reads
        return root / urlparse(urljoin(page, url)).path.lstrip("/")

    config = json.loads(served("./examples/checkpoints/g1/interaction_policy.json").read_text())  # defaultPolicy
    assert config["policy_type"] == "interaction" and config["lessmimic"]
    urls = fetched_files(config)
    assert set(urls) == {"onnx.path", "latent_encoder.path", "scene_xml", *(f"sdf.objects.{k}" for k in
                                                                           ("box", "chair", "crate"))}  # fmt: skip
    for key, url in urls.items():
        assert served(url).is_file(), (key, url)
    for key, name in (("onnx.path", "policy.onnx"), ("latent_encoder.path", "latent_encoder.onnx")):
        assert served(urls[key]) == site / "examples/checkpoints/g1" / name and urls[key] == VIEWER_URLS[name]
        onnx.checker.check_model(onnx.load(str(served(urls[key]))))
        assert not served(name).exists()  # the old bare name resolves beside the page: nothing there
    inputs = {i.name for i in OnnxSession(served(urls["onnx.path"])).get_inputs()}
    assert inputs == set(DEMO_INPUTS)
