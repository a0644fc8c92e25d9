"""Render docs/images/vox_colors_house.png: a six-colour voxel house, its marching-cubes and
AGNDC meshes with each face coloured by the nearest voxel (agndc_core/study/voxel_art.py), and
write the house as a .vox beside it when asked (``--vox PATH``).

    .venv/bin/python research/vox_colors_figure.py [-o docs/images/vox_colors_house.png]
"""

import argparse
from pathlib import Path

from agndc_core.gridio import save_grid
from agndc_core.study.voxel_art import house, render_house_figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path,
                        default=Path("docs/images/vox_colors_house.png"))
    parser.add_argument("--vox", type=Path, help="also write the house as a MagicaVoxel file")
    args = parser.parse_args()
    used = render_house_figure(args.out)
    for method, index in used.items():
        print(f"{method}: {len(index):,} faces, colours {sorted(set(index.tolist()))}")
    if args.vox:
        save_grid(house(), args.vox)
    print(f"written: {args.out} ({args.out.stat().st_size / 1024:.0f} KB)")


if __name__ == "__main__":
    main()
