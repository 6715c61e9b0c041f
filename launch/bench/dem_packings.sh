#!/usr/bin/env bash
# Builds the dense beds of the DEM benchmark once, with LAMMPS and the decks of
# shared/peers/dem (both codes then read the same LAMMPS data files):
#   3D: static_20k.data, flow_20k.data, static_100k.data, flow_100k.data
#   2D: static_2d_10k.data, flow_2d_10k.data (the 50k beds are 5x1 replicas made at run time)
# usage: dem_packings.sh PEERS_DIR OUT_DIR       (installs Debian's lammps if `lmp` is missing)
set -euo pipefail
peers=$(cd "$1" && pwd)
out=$2
mkdir -p "$out"
cd "$out"
if ! command -v lmp >/dev/null 2>&1; then
    echo "dem_packings: installing LAMMPS (Debian package lammps)" >&2
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq lammps >/dev/null
fi
export OMP_NUM_THREADS=1
if [ ! -f flow_100k.data ]; then
    echo "dem_packings: 3D bed (20,000 spheres): loose lattice, settle, chute flow (a few minutes)" >&2
    python3 "$peers/gen_pack.py" bed3d 20000 30 loose3d.data 1
    lmp -in "$peers/dem_settle3d.in" -var infile loose3d.data -var outfile bed3d.data -log settle3d.log -screen none
    lmp -in "$peers/dem_prep3d.in" -var bed bed3d.data -log prep3d.log -screen none
fi
if [ ! -f flow_2d_10k.data ]; then
    echo "dem_packings: 2D bed (10,000 disks): loose lattice, settle, chute flow" >&2
    python3 "$peers/gen_pack.py" bed2d 10000 100 loose2d.data 1
    lmp -in "$peers/dem_settle2d.in" -var infile loose2d.data -var tag 10k -log settle2d.log -screen none
fi
ls -l ./*.data >&2
