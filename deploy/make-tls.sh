#!/usr/bin/env sh
# Make the certificates of a three-host deployment (run once, on the state host, from the checkout):
# a private CA (deploy/tls/ca.crt, ca.key) and the state host's certificate for STATE_HOST
# (deploy/tls/state.crt, state.key), which Redis (TLS) and MinIO (HTTPS) present. Copy ca.crt
# (never ca.key) to deploy/tls/ on the API and worker hosts: they trust the CA to reach Redis
# (rediss://...?ssl_ca_certs=/tls/ca.crt) and MinIO (AWS_CA_BUNDLE=/tls/ca.crt).
set -eu
cd "$(dirname "$0")"
. ./hosts.env
mkdir -p tls
cd tls
[ -f ca.key ] || openssl req -x509 -newkey rsa:4096 -nodes -days 3650 -subj "/CN=segue deployment CA" \
    -keyout ca.key -out ca.crt
openssl req -newkey rsa:2048 -nodes -subj "/CN=$STATE_HOST" -keyout state.key -out state.csr
printf 'subjectAltName=IP:%s\n' "$STATE_HOST" > state.ext
openssl x509 -req -in state.csr -CA ca.crt -CAkey ca.key -CAcreateserial -days 825 -extfile state.ext \
    -out state.crt
rm -f state.csr state.ext
chmod 644 ca.crt state.crt
chmod 600 ca.key state.key
echo "deploy/tls: ca.crt (copy it to the API and worker hosts), state.crt, state.key"
