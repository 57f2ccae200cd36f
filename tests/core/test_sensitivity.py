"""`lidarjax.sensitivity` and `lidarjax.uncertainty`: Jacobians against centred finite
differences of independently rebuilt inputs, batches, closed forms, GUM budgets against
their definition and a Monte Carlo, and the inverse's budget against `invert`'s own
uncertainty and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.sensitivity import sensitivity, uncertainty

HEIGHTS = np.array([10.0, 40.0, 90.0])
WRT = ("location", "beta", "gamma", "psi", "epsilon", "pitch", "roll", "cone_angle",
       "heights", "speed", "direction", "scene.half_width")
OUTS = ("lidar_speed", "lidar_direction", "lidar_w", "cff_U", "cff_th", "cfp_U", "los")
NOMINAL = dict(loc=np.array([30.0, -20.0, 48.0]), beta=20.0, gamma=5.0, psi=180.0, epsilon=3.0,
               pitch=1.5, roll=-2.0, cone=28.0, speed=10.0, direction=250.0, half_width=250.0)


def _config(**kw):
    p = {**NOMINAL, **kw}
    scene = lj.scenes.hill(50.0, p["half_width"], p["speed"], p["direction"], ridge_normal=70.0)
    mount = lj.Mount(p["loc"], p["beta"], p["gamma"], p["psi"], p["epsilon"], pitch=p["pitch"],
                     roll=p["roll"])
    u_ref = p["speed"] * np.array([-np.sin(np.radians(p["direction"])),
                                   -np.cos(np.radians(p["direction"])), 0.0])
    return scene, lj.windcube_v2(p["cone"]), mount, u_ref


def _outputs(sim):
    return {"lidar_speed": sim.lidar_speed, "lidar_direction": sim.lidar_direction,
            "lidar_w": sim.lidar_velocity[:, 2], "cff_U": sim.cff_U, "cff_th": sim.cff_th,
            "cfp_U": sim.cfp_U, "los": sim.los}


def _fd(name, eps):
    """Centred difference of every output for input `name`, inputs rebuilt from scratch."""
    def run(sign):
        kw, dh = {}, 0.0
        if name in ("x", "y", "z"):
            loc = NOMINAL["loc"].copy()
            loc["xyz".index(name)] += sign * eps
            kw["loc"] = loc
        elif name == "cone_angle":
            kw["cone"] = NOMINAL["cone"] + sign * eps
        elif name == "heights":
            dh = sign * eps
        elif name == "scene.half_width":
            kw["half_width"] = NOMINAL["half_width"] + sign * eps
        else:
            kw[name] = NOMINAL[name] + sign * eps
        scene, scan, mount, u_ref = _config(**kw)
        return _outputs(lj.simulate(scene, scan, mount, HEIGHTS + dh, u_ref=u_ref))

    plus, minus = run(1), run(-1)
    out = {}
    for k in plus:
        d = np.asarray(plus[k]) - np.asarray(minus[k])
        if k in ("lidar_direction", "cff_th"):
            d = (d + 180.0) % 360.0 - 180.0  # wrapped differences
        out[k] = d / (2 * eps)
    return out


@pytest.fixture(scope="module")
def sens():
    scene, scan, mount, u_ref = _config()
    return sensitivity(scene, scan, mount, HEIGHTS, u_ref=u_ref, wrt=WRT, outputs=OUTS)


def test_jacobians_match_finite_differences(sens):
    names = sens.inputs
    assert names[:3] == ("x", "y", "z") and len(names) == 14
    for i, name in enumerate(names):
        fd = _fd(name, 1e-4)
        for out in OUTS:
            j = np.asarray(sens.jacobian[out])[..., i]
            assert j.shape == np.asarray(sens.value[out]).shape
            scale = np.max(np.abs(np.asarray(sens.jacobian[out]))) + 1e-12
            np.testing.assert_allclose(j, fd[out], rtol=1e-5, atol=2e-7 * scale,
                                       err_msg=f"d {out} / d {name}")


def test_values_are_the_forward_model(sens):
    scene, scan, mount, u_ref = _config()
    sim = _outputs(lj.simulate(scene, scan, mount, HEIGHTS, u_ref=u_ref))
    for out in OUTS:
        np.testing.assert_allclose(np.asarray(sens.value[out]), np.asarray(sim[out]), rtol=1e-12)
    assert sens.units("lidar_speed", "pitch") == "m/s per deg"
    assert sens.units("cff_th", "x") == "deg per m"
    text = sens.table("lidar_speed")
    assert "pitch [deg]" in text and "scene.half_width [unit]" in text and len(text.splitlines()) == 5


def test_uniform_flow_closed_forms():
    """Level lidar in a uniform flow: the reported wind follows the free stream one to one,
    heading errors turn it degree for degree, and nothing else moves it to first order."""
    scene = lj.scenes.uniform(8.0, 300.0)
    sens = sensitivity(scene, lj.windcube_v1(), lj.Mount([0.0, 0.0, 0.0]), HEIGHTS,
                       wrt=("location", "epsilon", "gamma", "pitch", "roll", "speed",
                            "direction"), outputs=("lidar_speed", "lidar_direction", "cff_U"))
    j = {o: np.asarray(sens.jacobian[o]) for o in sens.outputs}
    col = {n: i for i, n in enumerate(sens.inputs)}
    np.testing.assert_allclose(j["lidar_speed"][:, col["speed"]], 1.0, rtol=1e-12)
    np.testing.assert_allclose(j["lidar_direction"][:, col["direction"]], 1.0, rtol=1e-12)
    # the software north offset and the lidar-to-platform angle turn the report
    np.testing.assert_allclose(j["lidar_direction"][:, col["epsilon"]], 1.0, rtol=1e-12)
    np.testing.assert_allclose(j["lidar_direction"][:, col["gamma"]], 1.0, rtol=1e-12)
    # uniform flow: location does nothing, a tilt changes the speed at second order only
    for n in ("x", "y", "z", "pitch", "roll"):
        np.testing.assert_allclose(j["lidar_speed"][:, col[n]], 0.0, atol=1e-12)
        np.testing.assert_allclose(j["cff_U"][:, col[n]], 0.0, atol=1e-12)
    # the scene's free stream is inferred: the correction factor does not move with speed
    np.testing.assert_allclose(j["cff_U"][:, col["speed"]], 0.0, atol=1e-12)


def test_bad_inputs_raise_before_compiling():
    scene, scan, mount, u_ref = _config()
    grid = lj.GridField.from_function(scene.sample, *(np.arange(0.0, 50.0, 10.0),) * 3)
    with pytest.raises(ValueError, match="unknown input 'tilt'"):
        sensitivity(scene, scan, mount, HEIGHTS, wrt=("tilt",))
    with pytest.raises(ValueError, match="unknown output"):
        sensitivity(scene, scan, mount, HEIGHTS, outputs=("speed_lidar",))
    with pytest.raises(ValueError, match="rotate the platform with 'beta'"):
        sensitivity(grid, scan, mount, HEIGHTS, u_ref=u_ref, wrt=("direction",))
    with pytest.raises(ValueError, match="needs `u_ref`"):
        sensitivity(grid, scan, mount, HEIGHTS, outputs=("cff_U",))
    with pytest.raises(ValueError, match="no float parameter 'radius'"):
        sensitivity(scene, scan, mount, HEIGHTS, wrt=("scene.radius",))
    with pytest.raises(ValueError, match="needs a response table"):
        sensitivity(scene, scan, mount, HEIGHTS, outputs=("inv_speed",))
    with pytest.raises(ValueError, match="finite and >= 0"):
        uncertainty(scene, scan, mount, HEIGHTS, std={"pitch": -1.0})
    with pytest.raises(ValueError, match="has no std"):
        uncertainty(scene, scan, mount, HEIGHTS, std={"pitch": 0.1}, correlation={("pitch", "roll"): 0.5})
    with pytest.raises(ValueError, match="not positive semi-definite"):
        uncertainty(scene, scan, mount, HEIGHTS, std={"pitch": 0.1, "roll": 0.1, "epsilon": 1.0},
                    correlation=np.array([[1, 0.9, -0.9], [0.9, 1, 0.9], [-0.9, 0.9, 1]]))


# ------------------------------------------------------------------------------------------
# Uncertainty budgets

STD = {"location": 0.05, "epsilon": 0.5, "pitch": 0.3, "roll": 0.3, "cone_angle": 0.1}


@pytest.fixture(scope="module")
def budget():
    scene, scan, mount, u_ref = _config()
    return uncertainty(scene, scan, mount, HEIGHTS, u_ref=u_ref, std=STD,
                       correlation={("pitch", "roll"): 0.4})


def test_budget_is_the_gum_law_with_correlations(budget):
    assert budget.inputs == ("x", "y", "z", "epsilon", "pitch", "roll", "cone_angle")
    u = np.array([0.05, 0.05, 0.05, 0.5, 0.3, 0.3, 0.1])
    corr = np.eye(7)
    corr[4, 5] = corr[5, 4] = 0.4
    cov = np.outer(u, u) * corr
    for o in budget.outputs:
        j = np.asarray(budget.jacobian[o])
        want = np.sqrt(np.einsum("hi,ij,hj->h", j, cov, j))
        np.testing.assert_allclose(np.asarray(budget.std[o]), want, rtol=1e-12)
        np.testing.assert_allclose(np.asarray(budget.contribution[o]), np.abs(j) * u, rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_allclose(np.asarray(budget.share[o]).sum(-1), 1.0, rtol=1e-10)
    # the heading uncertainty turns the reported direction one to one
    np.testing.assert_allclose(np.asarray(budget.contribution["lidar_direction"])[:, 3], 0.5,
                               rtol=1e-10)


def test_second_order_budget_of_a_tilted_lidar_matches_monte_carlo():
    """A nearly level lidar's speed is stationary in its tilt (the cosine error): the first
    order misses most of it, the second-order term tr((H C)^2)/2 restores it. The sampled
    north offset gives exactly its own spread in the direction (wrapped across north)."""
    scene = lj.scenes.uniform(10.0, 359.9)
    b = uncertainty(scene, lj.windcube_v2(), lj.Mount([0.0, 0.0, 0.0], pitch=0.379, roll=0.262),
                    HEIGHTS[:1], std={"epsilon": 2.0, "pitch": 1.0, "roll": 1.0},
                    outputs=("lidar_speed", "lidar_direction"), n_monte_carlo=5000, key=0,
                    second_order=True)
    u, lin, so = (np.asarray(x["lidar_speed"])[0] for x in (b.std, b.std_linear, b.second_order))
    assert so > 1.5 * lin  # the cosine error dominates
    # closed form: the body-frame horizontal speed is U (1 - (r^2 x^2 + p^2 y^2 - 2 x y p r)/2)
    # (x, y the wind's unit components), so tr((H C)^2) / 2 = U^2 s^4 / 2 for tilt std s
    s = np.radians(1.0)
    np.testing.assert_allclose(so, 10.0 * s**2 / np.sqrt(2.0), rtol=1e-3)  # p0, r0 != 0
    np.testing.assert_allclose(u, np.sqrt(lin**2 + so**2), rtol=1e-12)
    assert abs(float(b.mc_relative_difference["lidar_speed"][0])) < 0.05
    z = jax.random.normal(jax.random.split(jax.random.PRNGKey(0), 2)[0], (5000, 3))
    want = np.std(2.0 * np.asarray(z[:, 0]), ddof=1)  # epsilon is the first input
    np.testing.assert_allclose(np.asarray(b.mc_std["lidar_direction"]), want, rtol=2e-3)
    assert "2nd order" in b.table("lidar_speed")


# ------------------------------------------------------------------------------------------
# The inverse


U_SHARED = np.array([1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def site():
    mount = lj.Mount([4.0, 3.0, 20.4])
    scan = lj.windcube_v2()
    h = np.array([10.0, 40.0])
    dirs = np.arange(0.0, 360.0, 15.0)
    sims = [lj.simulate(lj.scenes.hemisphere(20.0, 1.0, d), scan, mount, h,
                        u_ref=np.asarray(lj.heading(d))) for d in dirs]
    table = lj.ResponseTable.from_simulations(sims, mount=mount)
    return mount, scan, h, table


@pytest.fixture(scope="module")
def inverse_budget(site):
    """At a tabulated direction (the table is exact there), with a Monte Carlo of
    installation errors and record noise; as a batch of one sector (the sector axis)."""
    mount, scan, h, table = site
    scenes = [lj.scenes.hemisphere(20.0, 12.0, 240.0)]
    b = uncertainty(scenes, scan, mount, h, std={"gamma": 0.5, "x": 0.1, "speed": 1.0},
                    table=table, noise=0.1, n_monte_carlo=3000, key=1)
    return scenes, b


def test_inverse_budget_against_invert(site, inverse_budget):
    mount, scan, h, table = site
    scenes, b = inverse_budget
    assert b.inputs == ("gamma", "x", "speed", "los_noise")
    np.testing.assert_allclose(np.asarray(b.value["inv_speed"])[0], 12.0, rtol=1e-8)
    np.testing.assert_allclose(np.asarray(b.value["inv_direction"])[0], 240.0, atol=1e-7)
    j = {o: np.asarray(b.jacobian[o]) for o in ("inv_speed", "inv_direction")}
    # the inverse recovers a change of the free-stream speed one to one
    np.testing.assert_allclose(j["inv_speed"][0, :, 2], 1.0, rtol=1e-8)
    for k, scene in enumerate(scenes):
        # the record-noise term is invert's own Jacobian uncertainty with that noise
        sim = lj.simulate(scene, scan, mount, h, u_ref=U_SHARED)  # the table's compilation
        inv = lj.invert(table, sim.los[None], noise=0.1, batch_size="all")
        np.testing.assert_allclose(np.asarray(b.contribution["inv_speed"])[k, :, 3],
                                   np.asarray(inv.speed_std[0]), rtol=1e-6)
        np.testing.assert_allclose(np.asarray(b.contribution["inv_direction"])[k, :, 3],
                                   np.asarray(inv.direction_std[0]), rtol=1e-6)
        # installation terms: finite differences of invert(simulate(perturbed mount))
        for i, (name, eps) in enumerate((("gamma", 1e-3), ("x", 1e-3))):
            def run(sign, name=name, eps=eps, scene=scene):
                loc = np.array([4.0, 3.0, 20.4])
                g = 0.0
                if name == "x":
                    loc[0] += sign * eps
                else:
                    g = sign * eps
                los = lj.simulate(scene, scan, lj.Mount(loc, gamma=g), h, u_ref=U_SHARED).los
                r = lj.invert(table, los[None], batch_size="all")
                return np.asarray(r.speed[0]), np.asarray(r.direction[0])
            (s1, d1), (s0, d0) = run(1), run(-1)
            np.testing.assert_allclose(j["inv_speed"][k, :, i], (s1 - s0) / (2 * eps),
                                       rtol=1e-4, atol=1e-7)
            np.testing.assert_allclose(j["inv_direction"][k, :, i],
                                       ((d1 - d0 + 180) % 360 - 180) / (2 * eps), rtol=1e-4,
                                       atol=1e-6)
    # a heading error turns the corrected direction nearly one to one
    np.testing.assert_allclose(j["inv_direction"][..., 0], 1.0, atol=0.05)
    # the forward outputs see no record noise
    np.testing.assert_allclose(np.asarray(b.jacobian["lidar_speed"])[..., 3], 0.0)


def test_inverse_budget_monte_carlo(inverse_budget):
    _, b = inverse_budget
    for o in ("inv_speed", "inv_direction"):
        rel = np.asarray(b.mc_relative_difference[o])
        assert np.all(np.abs(rel) < 0.06), (o, rel)
    # both kinds of term matter for the direction: record noise and the heading
    share = np.asarray(b.share["inv_direction"])
    assert share[..., 3].max() > 0.05 and share[..., 0].min() > 0.3
    assert jnp.all(jnp.isfinite(b.std["inv_speed"]))


def test_batched_mount_sensitivity_equals_single_mounts():
    """A batched Mount (three platform rotations from arrays) gives each rotation's own
    Jacobian, as separate calls do."""
    scene = lj.scenes.uniform(8.0, 300.0)
    betas = np.array([0.0, 40.0, 130.0])
    kw = dict(wrt=("beta", "pitch", "x"), outputs=("lidar_speed", "lidar_direction"))
    batch = sensitivity(scene, lj.windcube_v1(), lj.Mount([1.0, 2.0, 3.0], beta=betas, pitch=1.0),
                        HEIGHTS, **kw)
    assert batch.jacobian["lidar_direction"].shape == (3, 3, 3)
    for k, b in enumerate(betas):
        one = sensitivity(scene, lj.windcube_v1(), lj.Mount([1.0, 2.0, 3.0], beta=b, pitch=1.0),
                          HEIGHTS, **kw)
        for o in kw["outputs"]:
            np.testing.assert_allclose(np.asarray(batch.jacobian[o])[k], one.jacobian[o],
                                       rtol=1e-12, atol=1e-14)
    # uniform flow: the platform rotation turns the report degree for degree (as gamma does),
    # to within the coupling of the 1-degree tilt (~1e-4)
    np.testing.assert_allclose(np.asarray(batch.jacobian["lidar_direction"])[..., 0], 1.0,
                               rtol=5e-4)


def test_monte_carlo_batch_default_and_validation():
    """`mc_batch_size=None` picks the backend's chunk (256 here, on a CPU): the same draws, so
    the same Monte Carlo, as an explicit chunk; bad chunks are refused before compiling."""
    scene = lj.scenes.uniform(10.0, 200.0)
    kw = dict(std={"epsilon": 1.0}, outputs=("lidar_direction",), n_monte_carlo=300, key=4)
    mount = lj.Mount([0.0, 0.0, 0.0])
    auto = uncertainty(scene, lj.windcube_v1(), mount, HEIGHTS[:1], **kw)
    fixed = uncertainty(scene, lj.windcube_v1(), mount, HEIGHTS[:1], mc_batch_size=100, **kw)
    np.testing.assert_allclose(auto.mc_std["lidar_direction"], fixed.mc_std["lidar_direction"],
                               rtol=1e-12)
    np.testing.assert_allclose(auto.mc_std["lidar_direction"], 1.0, rtol=0.15)
    for bad in (0, 2.5, "all"):
        with pytest.raises(ValueError, match="`mc_batch_size` must be a positive int or None"):
            uncertainty(scene, lj.windcube_v1(), mount, HEIGHTS[:1], mc_batch_size=bad, **kw)
