#!/usr/bin/env bash
# QEMU's user-mode x86-64 emulator for the test that runs an int8 model on an older CPU (`make qemu`):
# `qemu-x86_64-static -cpu Haswell` runs a program as on a CPU with AVX2 but without AVX-512 or VNNI,
# where onnxruntime takes other int8 kernels than on this machine (models/training/export.py,
# WEIGHT_TYPE). From Debian's qemu-user-static package (60 MB); `apt-get download` and `dpkg-deb`
# need no install and no root; only when apt's package lists lack it (a fresh container) is
# `apt-get update` run, which needs root. Only the one static binary (11 MB) and the copyright stay, in
#   ${XDG_CACHE_HOME:-~/.cache}/superbody/qemu   (or the folder given as $1)
# Idempotent: a binary that runs is not fetched again.
set -euo pipefail

out=${1:-${XDG_CACHE_HOME:-$HOME/.cache}/superbody/qemu}
bin=qemu-x86_64-static
have_qemu() { [ -x "$out/$bin" ] && "$out/$bin" --version >/dev/null 2>&1; }
if have_qemu; then
    echo "qemu: $out/$bin ($("$out/$bin" --version | head -n 1))"
    exit 0
fi
mkdir -p "$(dirname "$out")"
if command -v flock >/dev/null; then  # one fetch at a time (two `make test` at once); the second then finds it
    exec 9>"$out.lock"
    flock 9
    if have_qemu; then
        echo "qemu: $out/$bin ($("$out/$bin" --version | head -n 1))"
        exit 0
    fi
fi
for tool in apt-get dpkg-deb; do
    command -v "$tool" >/dev/null || { echo "qemu: needs $tool (Debian or Ubuntu); elsewhere put a static qemu-x86_64 at $out/$bin" >&2; exit 1; }
done

tmp=$(mktemp -d "$out.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
chmod 755 "$tmp"  # apt downloads as the _apt user when it can write there
cd "$tmp"
start=$SECONDS
if ! apt-get download qemu-user-static >apt.log 2>&1; then
    if [ "$(id -u)" -ne 0 ]; then
        cat apt.log >&2
        echo "qemu: apt-get download qemu-user-static failed; if apt's package lists are missing, run 'sudo apt-get update' and try again" >&2
        exit 1
    fi
    apt-get update -qq >apt.log 2>&1 || { cat apt.log >&2; exit 1; }
    apt-get download qemu-user-static >apt.log 2>&1 || { cat apt.log >&2; exit 1; }
fi
deb=$(ls qemu-user-static_*.deb)
dpkg-deb --fsys-tarfile "$deb" | tar -x "./usr/bin/$bin" ./usr/share/doc/qemu-user-static/copyright
mkdir -p keep
mv "./usr/bin/$bin" keep/
mv ./usr/share/doc/qemu-user-static/copyright keep/COPYRIGHT-qemu-user-static
keep/$bin --version >/dev/null || { echo "qemu: $deb's $bin does not run here" >&2; exit 1; }
rm -rf "$out"
mv keep "$out"
echo "qemu: $deb -> $out/$bin ($((SECONDS - start)) s)"
