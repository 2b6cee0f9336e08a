"""The starting weights of the pipe's section model (``README.md`` beside this file): the middle
section (zeta = 1/2) of a pipe model of 3D networks, one per block, as 2D networks, in a section
checkpoint that gives the rest (normalisation, extrusion, loss weights, configuration).

    python benchmarks/models/pipe/section_start.py OLD_3D.pt SECTION_RUN.pt OUT.pt

The 3D network's first layer sees 2 zeta - 1 = 0 at zeta = 1/2, so its zeta column drops out; its
last layer's x and y rows are rescaled from the 3D model's normalisation (centre c3, scale s3) to
the section's (c2, s2): x = (s3 y3 + c3 - c2) / s2. The 2D networks then give the 3D networks'
middle section exactly (in the section's normalised units).
"""

import sys

import torch


def main(old_path: str, section_path: str, out_path: str) -> None:
    old = torch.load(old_path, weights_only=True)
    section = torch.load(section_path, weights_only=True)
    if "extruded" in old["model"] or "extruded" not in section["model"] or old["model"]["blocks"] != section["model"]["blocks"]:
        raise SystemExit("need a pipe model of 3D networks and a section checkpoint of the same blocks")
    c3, s3 = torch.tensor(old["model"]["center"][:2], dtype=torch.float64), float(old["model"]["scale"])
    c2, s2 = torch.tensor(section["model"]["center"], dtype=torch.float64), float(section["model"]["scale"])
    last = max(int(key.split(".")[3]) for key in section["model"]["state_dict"])
    weights = {}
    for key, template in section["model"]["state_dict"].items():
        value = old["model"]["state_dict"][key].double()
        layer, kind = int(key.split(".")[3]), key.split(".")[4]
        if layer == 0 and kind == "weight":
            value = value[:, :2]
        elif layer == last:
            value = value[:2] * s3 / s2 if kind == "weight" else (value[:2] * s3 + c3 - c2) / s2
        if value.shape != template.shape:
            raise SystemExit(f"{key}: {tuple(value.shape)} against the section's {tuple(template.shape)}: not the same widths")
        weights[key] = value.to(template.dtype).clone()
    section["model"]["state_dict"] = weights
    section["optimizer"], section["scheduler"] = {}, {}
    torch.save(section, out_path)


if __name__ == "__main__":
    main(*sys.argv[1:4])
