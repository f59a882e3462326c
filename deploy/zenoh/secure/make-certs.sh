#!/usr/bin/env sh
# Make a private CA and one certificate per process for the secure profile (a test or
# bench set-up; for a vehicle fleet use your organisation's PKI the same way).
#
#   deploy/zenoh/secure/make-certs.sh OUTDIR [ROUTER_ADDRESS ...]
#
# OUTDIR receives ca.pem (the root every process trusts), ca-key.pem (keep it off the
# vehicle), router.pem/router-key.pem (names: 127.0.0.1, localhost and every
# ROUTER_ADDRESS, e.g. 192.168.10.1) and <name>.pem/<name>-key.pem for radar, camera,
# fusion-primary, fusion-candidate, brake and monitor (common name = that name, which the
# router's access control matches; one per fusion instance). Keys are EC P-256,
# certificates valid 825 days. Another fusion instance: add its name to the list below.
set -eu
out=${1:?usage: make-certs.sh OUTDIR [ROUTER_ADDRESS ...]}
shift
mkdir -p "$out"
cd "$out"
days=825

key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

key ca-key.pem
openssl req -x509 -new -key ca-key.pem -out ca.pem -days "$days" -subj "/CN=aeb-ca" \
  -addext "basicConstraints=critical,CA:TRUE" \
  -addext "keyUsage=critical,keyCertSign,cRLSign"

leaf() {  # leaf NAME SUBJECT_ALT_NAMES EXTENDED_KEY_USAGE
  key "$1-key.pem"
  openssl req -new -key "$1-key.pem" -out "$1.csr" -subj "/CN=$1"
  printf 'basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\nextendedKeyUsage=%s\nsubjectAltName=%s\n' \
    "$3" "$2" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca-key.pem -CAcreateserial \
    -out "$1.pem" -days "$days" -extfile "$1.ext" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}

sans="IP:127.0.0.1,DNS:localhost"
for addr in "$@"; do
  case "$addr" in
    *[!0-9.]*) sans="$sans,DNS:$addr" ;;
    *) sans="$sans,IP:$addr" ;;
  esac
done
leaf router "$sans" "serverAuth,clientAuth"
for svc in radar camera fusion-primary fusion-candidate brake monitor; do
  leaf "$svc" "DNS:$svc" "clientAuth"
done
chmod 600 ./*-key.pem
echo "certificates in $(pwd): ca.pem router.pem radar.pem camera.pem fusion-primary.pem" \
  "fusion-candidate.pem brake.pem monitor.pem"
