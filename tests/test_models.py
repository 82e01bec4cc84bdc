"""nik.models: the IK network, its buffers and safe checkpoints."""

from __future__ import annotations

import math

import pytest
import torch

import nik
from nik.models import IKNet, load_checkpoint, save_checkpoint


@pytest.fixture(scope="module")
def kuka():
    return nik.load_robot("kuka_kr")


@pytest.fixture(scope="module")
def samples(kuka):
    q = kuka.sample(256, generator=torch.Generator().manual_seed(1))
    return kuka.fk(q), q


@pytest.mark.parametrize("representation,dim", [("rpy", 6), ("quat", 7), ("rot6d", 9)])
@pytest.mark.parametrize("output", ["angles", "sincos"])
def test_shapes_and_limits(kuka, samples, representation, dim, output):
    T, q = samples
    net = IKNet(kuka, hidden=[16, 16], activation="silu", representation=representation, output=output)
    net.fit_normalisation(T, q)
    assert net.in_dim == dim
    assert net.raw(net.features(T)).shape == (256, kuka.dof * (2 if output == "sincos" else 1))
    pred = net.predict(T.double())
    assert pred.shape == (256, kuka.dof) and pred.dtype == torch.float64
    assert bool(kuka.within_limits(pred).all())


def test_paper_c_net_has_110_parameters(kuka):
    net = IKNet(kuka, hidden=[8], activation="tanh", representation="rpy")
    assert net.n_params == 6 * 8 + 8 + 8 * 6 + 6
    assert repr(net).startswith("IKNet(6-8-6, tanh")


def test_normalisation_standardises_inputs_and_maps_training_range(kuka, samples):
    T, q = samples
    net = IKNet(kuka).fit_normalisation(T, q)
    x = net.features(T)
    torch.testing.assert_close(x.mean(0), torch.zeros(6), atol=1e-5, rtol=0)
    torch.testing.assert_close(x.std(0), torch.ones(6), atol=1e-5, rtol=0)
    y = net.encode(q)
    torch.testing.assert_close(y.amin(0), -torch.ones(6), atol=1e-6, rtol=0)
    torch.testing.assert_close(y.amax(0), torch.ones(6), atol=1e-6, rtol=0)
    torch.testing.assert_close(net.decode(y), q, atol=1e-5, rtol=0)


def test_sincos_decodes_within_one_turn_of_the_range_centre(kuka):
    net = IKNet(kuka, output="sincos")
    q = torch.tensor([[0.5, -1.0, 0.3, 2.5, -1.5, -3.0]])
    torch.testing.assert_close(net.decode(net.encode(q)), q, atol=1e-6, rtol=0)


@pytest.mark.parametrize("output", ["angles", "sincos"])
def test_prismatic_joint_is_decoded_linearly(output):
    robot = nik.load_robot("stanford")
    net = IKNet(robot, output=output)
    q = robot.sample(64, generator=torch.Generator().manual_seed(0), dtype=torch.float32)
    torch.testing.assert_close(net.decode(net.encode(q)), q, atol=1e-5, rtol=0)
    y = torch.zeros(1, net.out_dim)
    y[0, 2 if output == "angles" else 4] = 1.0  # the slide's (first) output at +1
    q_top = net.decode(y)[0, 2]
    torch.testing.assert_close(q_top, robot.limits[2, 1].float())  # linear: +1 is the top of the range
    if output == "sincos":
        y[0, 5] = 5.0  # the slide's second output plays no part
        torch.testing.assert_close(net.decode(y)[0, 2], q_top)
        assert float(net.encode(q)[:, 5].abs().max()) == 0.0


def test_bad_configuration_is_refused(kuka):
    with pytest.raises(ValueError, match="activation"):
        IKNet(kuka, activation="sigmoidish")
    with pytest.raises(ValueError, match="representation"):
        IKNet(kuka, representation="euler")
    with pytest.raises(ValueError, match="predict"):
        IKNet(kuka).predict(torch.eye(4))


def test_checkpoint_roundtrip_is_exact_and_safe(kuka, samples, tmp_path):
    T, q = samples
    torch.manual_seed(0)
    net = IKNet(kuka, hidden=[32], activation="gelu", representation="quat", output="sincos").fit_normalisation(T, q)
    path = save_checkpoint(net, tmp_path / "net.ckpt")
    raw = torch.load(path, weights_only=True)  # plain data only
    assert raw["nik"]["robot_hash"] == kuka.definition_hash
    back = load_checkpoint(path, robot="kuka_kr")
    assert back.config() == net.config()
    assert back.robot.definition_hash == kuka.definition_hash
    assert torch.equal(back.predict(T), net.predict(T))


def test_checkpoint_for_another_robot_is_refused(kuka, tmp_path):
    path = save_checkpoint(IKNet(kuka), tmp_path / "kuka.ckpt")
    with pytest.raises(nik.CheckpointError, match=r"'kuka_kr'.*'puma560'"):
        load_checkpoint(path, robot="puma560")


def test_not_a_checkpoint_is_refused(tmp_path):
    path = tmp_path / "junk.ckpt"
    torch.save({"state_dict": {}}, path)
    with pytest.raises(nik.CheckpointError, match="not a loadable nik checkpoint"):
        load_checkpoint(path)
    with pytest.raises(FileNotFoundError):
        load_checkpoint(tmp_path / "missing.ckpt")


def test_a_folder_given_as_checkpoint_is_named_a_folder(tmp_path, capsys):
    from nik.cli import main
    from nik.errors import CheckpointError

    folder = tmp_path / "runs"
    folder.mkdir()
    with pytest.raises(CheckpointError, match=r"runs is a folder, not a checkpoint file"):
        load_checkpoint(folder)
    assert (
        main(["solve", "--robot", "kuka_kr", "--checkpoint", str(folder), "--pose", "1", "0", "1", "1", "0", "0", "0"])
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a folder" in err and "not found" not in err


def test_predict_angles_follow_fk_for_a_perfect_lookup(kuka):
    # decode(encode(q)) is the identity, so a net whose raw output were exact would reproduce q
    q = kuka.sample(8, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    net = IKNet(kuka).double()
    assert math.isclose(float((net.decode(net.encode(q)) - q).abs().max()), 0.0, abs_tol=1e-12)
