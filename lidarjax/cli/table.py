"""`lidarjax table`: a response table of CFD runs over directions, for `correct`."""

from __future__ import annotations

from ._common import add_run_arguments, field_paths, make_probe, make_scan
from ._dask import add_dask_arguments, dask_client, region_loader


def register(sub) -> None:
    tab = sub.add_parser(
        "table", help="build a response table (for `correct`) from CFD runs over directions",
        description="Simulate the lidar of a seed settings.dat in every CFD run (one per "
                    "platform rotation beta, i.e. per inflow direction) and save the LOS "
                    "per unit free-stream speed as a response table (.npz).",
        epilog="example: lidarjax table settings.dat --field 'runs/platform_{beta}.npz' "
               "--scan windcube_v2 --out site_table.npz")
    tab.add_argument("settings", help="the seed's settings.dat (all beta rows are used)")
    add_run_arguments(tab, default_scan="windcube_v2")
    tab.add_argument("--out", required=True, help="table file to write (.npz)")
    add_dask_arguments(tab)
    tab.set_defaults(func=run)



def run(args) -> int:
    from pathlib import Path

    from ..io import read_settings, save_table
    from ..io.fields import load_field
    from ..workflow import build_table, table_region

    settings = read_settings(args.settings)
    betas = [float(b) for b in settings.betas]
    paths = field_paths(args, betas)
    scan = make_scan(args.scan, args.cone_angle)
    probe = make_probe(args)
    out = Path(args.out)
    if not out.parent.is_dir():
        raise FileNotFoundError(f"output folder not found: {out.parent}")
    region = table_region(settings, betas, scan, probe=probe)
    with dask_client(args) as client:
        table, _ = build_table(settings, betas, region_loader(load_field, paths, region), scan,
                               u_ref=args.u_ref, probe=probe, client=client, progress=True)
    meta = {"settings": str(args.settings), "field": args.field, "scan": args.scan,
            "cone_angle_deg": float(scan.cone_angle), "probe": args.probe,
            "gamma_deg": settings.gamma, "psi_deg": settings.psi,
            "epsilon_deg": settings.epsilon, "u_ref_cfd_m_s": list(args.u_ref)}
    save_table(out, table, meta)
    print(f"response table: {table.n_directions} directions x {table.n_heights} heights x "
          f"{table.n_beams} beams -> {out}")
    return 0
