#!/usr/bin/env bash
# A throwaway certificate authority and the certificates of mutual TLS for the Zenoh gateway
# (config/zenoh/gateway-tls.json5): the gateway's server certificate and one client certificate
# per account, each named by its common name (the ACL's cert_common_names).
#
#   tools/make_certs.sh DIR [HOST ...] [--clients NAME ...]
#
# DIR gets ca.pem (give it to every peer), ca.key (keep it offline: whoever has it can issue
# an operator's certificate), gateway.pem/gateway.key (the daemon's), and NAME.pem/NAME.key
# for each client (default: operator viewer). HOSTs are the names and addresses peers connect
# to (default: localhost 127.0.0.1); they go into the gateway certificate's subjectAltName.
# Keys are EC P-256, certificates valid 825 days, files 0600 but the public ones.
set -euo pipefail
if [[ $# -lt 1 || "$1" == -* ]]; then
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
dir=$1; shift
hosts=(); clients=()
while [[ $# -gt 0 ]]; do
  if [[ "$1" == "--clients" ]]; then shift; clients=("$@"); break; fi
  hosts+=("$1"); shift
done
[[ ${#hosts[@]} -gt 0 ]] || hosts=(localhost 127.0.0.1)
[[ ${#clients[@]} -gt 0 ]] || clients=(operator viewer)
command -v openssl >/dev/null || { echo "make_certs.sh: openssl is needed" >&2; exit 1; }
mkdir -p "$dir"
umask 077
cd "$dir"
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

key ca.key
openssl req -x509 -new -key ca.key -sha256 -days 825 -subj "/CN=cdprctl throwaway CA" \
  -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
  -out ca.pem

san=""
for h in "${hosts[@]}"; do
  if [[ "$h" =~ ^[0-9.]+$ || "$h" == *:* ]]; then san+="IP:$h,"; else san+="DNS:$h,"; fi
done
issue() {  # name, common name, extendedKeyUsage, subjectAltName (optional)
  key "$1.key"
  openssl req -new -key "$1.key" -subj "/CN=$2" -out "$1.csr"
  {
    echo "basicConstraints=critical,CA:FALSE"
    echo "keyUsage=critical,digitalSignature"
    echo "extendedKeyUsage=$3"
    [[ -n "${4:-}" ]] && echo "subjectAltName=$4"
  } > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -sha256 -days 825 \
    -extfile "$1.ext" -out "$1.pem" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
}
issue gateway cdprctl-gateway serverAuth,clientAuth "${san%,}"
for c in "${clients[@]}"; do issue "$c" "$c" clientAuth; done
rm -f ca.srl
chmod 0644 ca.pem ./*.pem
echo "make_certs.sh: wrote $(cd "$OLDPWD" && cd "$dir" && pwd): ca.pem ca.key gateway.pem gateway.key ${clients[*]/%/.pem}"
