#!/usr/bin/env bash
# The measurements of results/mpi_scaling.md, on loopback:
#   scripts/mpi_scaling.sh bytes BUILD OUT   bytes exchanged a pass and a frame (car, texture-
#                                            space path at the hits) by resolution and ranks
#   scripts/mpi_scaling.sh pingpong BUILD    latency and bandwidth between two ranks
#   scripts/mpi_scaling.sh ab BUILD N        2 ranks x 1 thread against 1 rank x 2 threads,
#                                            alternating, N runs each: render seconds, medians
#   scripts/mpi_scaling.sh model OUT_PREFIX CORE_SECONDS U F
#                                            the scaling model of a pass (results/mpi_scaling.md):
#                                            CORE_SECONDS of compute a pass, U bytes of bins in
#                                            all, F bytes each rank sends whatever its share
set -euo pipefail
what="$1" build="${2:-}"
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
[ "$(id -u)" -ne 0 ] || export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none  # containers forbid its ptrace copies
mpi=(mpirun --oversubscribe)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
scene="$root/scenes/car.json"
opts=(--spp 4 --pass-spp 4 --shading texture --integrator path -q --no-png --seed 1)

case "$what" in
bytes)
    out="$3"
    echo "resolution,ranks,passes,pass_bytes,bytes_sent,bytes_received,seconds,cpu_seconds" >"$out"
    for res in ${RESOLUTIONS:-240x135 480x270 960x540}; do
        for np in ${RANKS:-2 3}; do
            "${mpi[@]}" -np "$np" "$build/bin/texcache" render "$scene" --resolution "$res" \
                "${opts[@]}" -o "$tmp/i.exr" --stats "$tmp/s.json" >/dev/null
            get() { sed -n "s/.*\"$1\": \([0-9.e+-]*\).*/\1/p" "$tmp/s.json"; }
            echo "$res,$np,$(get passes),$(get pass_bytes),$(get bytes_sent),$(get bytes_received),$(get seconds),$(get cpu_seconds)" |
                tee -a "$out"
        done
    done
    ;;
pingpong) "${mpi[@]}" -np 2 "$build/bin/mpi_pingpong" ;;
ab)
    n="$3" a=() b=()
    for i in $(seq "$n"); do
        # Alternating, so that the other load on the machine falls on both alike.
        a+=("$("${mpi[@]}" -np 2 "$build/bin/texcache" render "$scene" --resolution 480x270 \
            "${opts[@]}" --threads 1 -o "$tmp/a.exr" | sed -n 's/^time: \([0-9.]*\) s render.*/\1/p')")
        b+=("$("$build/bin/texcache" render "$scene" --resolution 480x270 "${opts[@]}" \
            --threads 2 -o "$tmp/b.exr" | sed -n 's/^time: \([0-9.]*\) s render.*/\1/p')")
        echo "run $i: 2 ranks x 1 thread ${a[-1]} s, 1 rank x 2 threads ${b[-1]} s"
    done
    median() { printf '%s\n' "$@" | sort -g | awk '{v[NR]=$1} END {print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}'; }
    ma="$(median "${a[@]}")" mb="$(median "${b[@]}")"
    echo "median: 2 ranks x 1 thread $ma s, 1 rank x 2 threads $mb s, ratio $(awk -v a="$ma" -v b="$mb" 'BEGIN{printf "%.3f", a/b}')"
    ;;
model)
    # A rank is a node of 32 cores as fast as this machine's; two interconnects (latency alpha,
    # bandwidth beta): InfiniBand HDR (2 us, 12 GB/s) and 10 Gb Ethernet (30 us, 1.1 GB/s).
    # A rank's bins of a pass: S(N) = U/N + F. Allgather (today's exchange): each rank
    # receives the others' bins, (N-1) S(N) bytes, over a ring of N-1 steps. Partitioned
    # (bins summed at a home rank by key, each rank fetching back those its hits read):
    # 2 S(N) bytes and 2 (N-1) messages, of which only ~min(N-1, 64) carry bins.
    out="$2" core="$3" u="$4" f="$5"
    awk -v core="$core" -v u="$u" -v f="$f" 'BEGIN {
        print "ranks,compute,allgather_ib,partitioned_ib,allgather_eth,partitioned_eth";
        for (n = 1; n <= 4096; n *= 2) {
            s = n > 1 ? u / n + f : 0; c = core / (32 * n);
            m = n - 1 < 64 ? n - 1 : 64;  # one rank alone exchanges nothing
            printf "%d,%g,%g,%g,%g,%g\n", n, c,
                c + (n - 1) * 2e-6 + (n - 1) * s / 12e9, c + 2 * m * 2e-6 + 2 * s / 12e9,
                c + (n - 1) * 30e-6 + (n - 1) * s / 1.1e9, c + 2 * m * 30e-6 + 2 * s / 1.1e9;
        }
    }' >"$out.csv"
    cat "$out.csv"
    gnuplot <<GP
set terminal pngcairo size 800,500
set output "$out.png"
set datafile separator ","
set logscale xy
set key top right
set grid
set title "3840x2160, one pass of 1 spp (car, path, texture space at the hits): model"
set xlabel "ranks (nodes of 32 cores)"
set ylabel "seconds a pass"
plot "$out.csv" using 1:2 with linespoints title "compute only", \
     "" using 1:3 with linespoints title "allgather, InfiniBand", \
     "" using 1:4 with linespoints title "partitioned, InfiniBand", \
     "" using 1:5 with linespoints title "allgather, 10 GbE", \
     "" using 1:6 with linespoints title "partitioned, 10 GbE"
GP
    ;;
*) echo "mpi_scaling.sh: error: unknown measurement '$what'" >&2; exit 2 ;;
esac
