#!/usr/bin/env bash
# Test certificates for the TLS tests, made with the openssl CLI (Debian: package openssl,
# which ca-certificates depends on). Usage: make_test_certs.sh OUT_DIR
# Writes, each as PEM:
#   ca.crt ca.key              the test CA
#   server.crt server.key      signed by it, for localhost / 127.0.0.1 / ::1
#   client.crt client.key      a client certificate signed by it (mTLS)
#   rogue-ca.crt rogue.crt rogue.key   another CA and a client certificate it signed
# Keys are EC P-256 (fast to make); certificates are valid for 2 days.
set -euo pipefail
out=${1:?usage: make_test_certs.sh OUT_DIR}
command -v openssl >/dev/null || { echo "make_test_certs: openssl not found (Debian: apt-get install openssl)" >&2; exit 1; }
mkdir -p "$out"
cd "$out"

key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

ca() {  # ca NAME SUBJECT
  key "$1.key"
  openssl req -x509 -new -key "$1.key" -sha256 -days 2 -subj "$2" -out "$1.crt" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign"
}

leaf() {  # leaf NAME CA SUBJECT EXTENSIONS
  key "$1.key"
  openssl req -new -key "$1.key" -subj "$3" -out "$1.csr"
  printf '%s\n' "$4" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA "$2.crt" -CAkey "$2.key" -CAcreateserial -sha256 -days 2 \
    -extfile "$1.ext" -out "$1.crt" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}

ca ca "/CN=catgs test CA"
leaf server ca "/CN=localhost" \
  "$(printf 'subjectAltName=DNS:localhost,IP:127.0.0.1,IP:::1\nextendedKeyUsage=serverAuth\nbasicConstraints=CA:FALSE')"
leaf client ca "/CN=catgs test client" "$(printf 'extendedKeyUsage=clientAuth\nbasicConstraints=CA:FALSE')"
ca rogue-ca "/CN=catgs rogue CA"
leaf rogue rogue-ca "/CN=catgs rogue client" "$(printf 'extendedKeyUsage=clientAuth\nbasicConstraints=CA:FALSE')"
openssl verify -CAfile ca.crt server.crt client.crt >/dev/null
echo "make_test_certs: certificates in $out"
