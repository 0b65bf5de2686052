#!/bin/sh
# Certificates, passwords and Zenoh configs for a secured superbody site (TLS, mutual TLS,
# user/password and an access-control list on the router).
#
#   deploy/zenoh/make-certs.sh OUT_DIR SITE CAMERA_ID...
#   e.g. ZENOH_HOST=router.lab.local deploy/zenoh/make-certs.sh /etc/superbody/zenoh wtf-apartment 1 2 3
#
# Writes into OUT_DIR: ca.pem (+ ca.key: keep it offline), one certificate and key per node
# (router, host, app, camera-<id>), credentials.txt (the router's user:password dictionary),
# and ready-to-use configs: router.json5, host.json5, app.json5, camera-<id>.json5.
# Copy to each machine only its own config, certificate and key, and ca.pem.
#
# Environment:
#   ZENOH_HOST     the router's DNS name or IP address, put in its certificate (default localhost)
#   ZENOH_LISTEN   the router's listening endpoint (default tls/0.0.0.0:7447)
#   ZENOH_CONNECT  the endpoint nodes connect to (default tls/$ZENOH_HOST:7447)
#   DAYS           certificate lifetime in days (default 825)
set -eu

usage() { echo "usage: $0 OUT_DIR SITE CAMERA_ID..." >&2; exit 2; }
[ $# -ge 3 ] || usage
OUT=$1; SITE=$2; shift 2
HERE=$(cd "$(dirname "$0")" && pwd)
HOST=${ZENOH_HOST:-localhost}
LISTEN=${ZENOH_LISTEN:-tls/0.0.0.0:7447}
CONNECT=${ZENOH_CONNECT:-tls/$HOST:7447}
DAYS=${DAYS:-825}

case "$SITE" in *[!A-Za-z0-9_-]*|"") echo "$0: SITE must be letters, digits, '_' or '-', got '$SITE'" >&2; exit 2;; esac
for cam in "$@"; do
  case "$cam" in *[!A-Za-z0-9_-]*|"") echo "$0: CAMERA_ID must be letters, digits, '_' or '-', got '$cam'" >&2; exit 2;; esac
done

mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
umask 077
cd "$OUT"

case "$HOST" in
  *[!0-9.]*) SAN="DNS:$HOST,DNS:localhost,IP:127.0.0.1" ;;
  *) SAN="IP:$HOST,DNS:localhost,IP:127.0.0.1" ;;
esac

# The site's own certificate authority (P-256 keys: small and fast).
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 -days "$DAYS" \
  -keyout ca.key -out ca.pem -subj "/CN=superbody-$SITE-ca" 2>/dev/null

issue() {  # issue NAME: a certificate whose common name is NAME (the ACL matches on it)
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
    -keyout "$1.key" -out "$1.csr" -subj "/CN=$1" 2>/dev/null
  printf 'basicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\nsubjectAltName=%s\n' "$SAN" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -sha256 -days "$DAYS" \
    -extfile "$1.ext" -out "$1.pem" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}

: > credentials.txt
node_config() {  # node_config NAME: certificate, password and config of one node
  issue "$1"
  pw=$(openssl rand -hex 16)
  echo "$1:$pw" >> credentials.txt
  sed -e "s|@NAME@|$1|g" -e "s|@PASSWORD@|$pw|g" -e "s|@DIR@|$OUT|g" -e "s|@CONNECT@|$CONNECT|g" \
    "$HERE/lan/node.json5.in" > "$1.json5"
}

issue router
node_config host
node_config app
RULES=""; SUBJECTS=""; POLICIES=""
for cam in "$@"; do
  node_config "camera-$cam"
  RULES="$RULES      { id: \"camera-$cam-publishes\", permission: \"allow\", flows: [\"ingress\"], messages: [\"put\", \"delete\", \"liveliness_token\"], key_exprs: [\"superbody/$SITE/cameras/$cam/**\"] },\n"
  SUBJECTS="$SUBJECTS      { id: \"camera-$cam\", cert_common_names: [\"camera-$cam\"], usernames: [\"camera-$cam\"] },\n"
  POLICIES="$POLICIES      { rules: [\"camera-$cam-publishes\", \"see-subscribers\"], subjects: [\"camera-$cam\"] },\n"
done

awk -v rules="$RULES" -v subjects="$SUBJECTS" -v policies="$POLICIES" '
  /@CAMERA_RULES@/ { printf "%s", rules; next }
  /@CAMERA_SUBJECTS@/ { printf "%s", subjects; next }
  /@CAMERA_POLICIES@/ { printf "%s", policies; next }
  { print }' "$HERE/lan/router.json5.in" \
  | sed -e "s|@SITE@|$SITE|g" -e "s|@DIR@|$OUT|g" -e "s|@LISTEN@|$LISTEN|g" > router.json5
rm -f ca.srl

echo "superbody: wrote $OUT: ca.pem, certificates and keys for router, host, app and camera-$(echo "$@" | sed 's/ /, camera-/g'), credentials.txt and their Zenoh configs" >&2
