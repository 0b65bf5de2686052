#!/usr/bin/env bash
# OpenCV's sample media for the detector tests (`make media`): vtest.avi (768 x 576, 795 frames at
# 10 fps: pedestrians seen by a fixed camera), basketball1.png (two people close up) and messi5.jpg
# (one player), from Debian's opencv-doc package (96 MB; OpenCV's samples are Apache-2.0 / BSD-3,
# the package's copyright file is kept beside them). `apt-get download` and `dpkg-deb` need no
# install and no root; only when apt's package lists lack opencv-doc (a fresh container) is
# `apt-get update` run, which needs root. Only the three files (8 MB) and the copyright stay, in
#   ${XDG_CACHE_HOME:-~/.cache}/superbody/opencv-media   (or the folder given as $1)
# Idempotent: files whose SHA-256 is right are not fetched again.
set -euo pipefail

out=${1:-${XDG_CACHE_HOME:-$HOME/.cache}/superbody/opencv-media}
# The bytes the tests were written against (opencv-doc 4.6.0+dfsg-12, Debian 12; the samples have not changed for years).
sums="45cddc9490be69345cbdab64ca583be65987e864ca408038e648db99e10516cf  vtest.avi
ba06f6701f7260998b430c39b6557f775497e6ce7b1a74f0b7ea6af371bf54a6  basketball1.png
1d570e49654e84c7a943918537bd9e5e1ef82920152e147c834006e235be97c9  messi5.jpg"

have_media() { [ -d "$out" ] && (cd "$out" && sha256sum --quiet -c - <<<"$sums" >/dev/null 2>&1); }
if have_media; then
    echo "media: $out has vtest.avi, basketball1.png and messi5.jpg"
    exit 0
fi
mkdir -p "$(dirname "$out")"
if command -v flock >/dev/null; then  # one fetch at a time (two `make test` at once); the second then finds the files
    exec 9>"$out.lock"
    flock 9
    if have_media; then
        echo "media: $out has vtest.avi, basketball1.png and messi5.jpg"
        exit 0
    fi
fi
for tool in apt-get dpkg-deb sha256sum; do
    command -v "$tool" >/dev/null || { echo "media: needs $tool (Debian or Ubuntu); elsewhere copy vtest.avi, basketball1.png and messi5.jpg from OpenCV's samples/data into $out" >&2; exit 1; }
done

tmp=$(mktemp -d "$out.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
chmod 755 "$tmp"  # apt downloads as the _apt user when it can write there
cd "$tmp"
start=$SECONDS
if ! apt-get download opencv-doc >apt.log 2>&1; then
    if [ "$(id -u)" -ne 0 ]; then
        cat apt.log >&2
        echo "media: apt-get download opencv-doc failed; if apt's package lists are missing, run 'sudo apt-get update' and try again" >&2
        exit 1
    fi
    apt-get update -qq >apt.log 2>&1 || { cat apt.log >&2; exit 1; }
    apt-get download opencv-doc >apt.log 2>&1 || { cat apt.log >&2; exit 1; }
fi
deb=$(ls opencv-doc_*.deb)
data=./usr/share/doc/opencv-doc/examples/data
dpkg-deb --fsys-tarfile "$deb" | tar -x "$data/vtest.avi" "$data/basketball1.png" "$data/messi5.jpg" ./usr/share/doc/opencv-doc/copyright
mkdir -p media
mv "$data/vtest.avi" "$data/basketball1.png" "$data/messi5.jpg" media/
mv ./usr/share/doc/opencv-doc/copyright media/COPYRIGHT-opencv-doc
if ! (cd media && sha256sum --quiet -c - <<<"$sums"); then
    echo "media: $deb holds other bytes than the tests were written against (see the SHA-256 sums in $0)" >&2
    exit 1
fi
rm -rf "$out"
mv media "$out"
echo "media: $deb -> $out ($((SECONDS - start)) s)"
