"""TLS for Zenoh links: a certificate authority, one certificate per piece, the config keys, and a
check that names what is wrong before a session tries to connect.

Zenoh 1.x reads TLS from ``transport/link/tls`` of a session's config (every ``tls/`` endpoint of
the session uses it)::

    root_ca_certificate     the CA that signs every piece's certificate (PEM)
    listen_certificate      a listening session's (the router's) certificate and private key
    listen_private_key
    connect_certificate     a connecting session's certificate and private key, shown to the
    connect_private_key     router under mutual TLS
    enable_mtls             true: each side must show a certificate signed by the CA
    verify_name_on_connect  true (default): the router's certificate must name the host connected to
    close_link_on_expiration  true: a link is closed when a certificate of it expires

:func:`make_ca` and :func:`issue` write the files (``swarmloc tls make-ca DIR``, ``swarmloc tls
issue DIR NAME``); :func:`apply_tls` fills those keys; :func:`check_tls` is what
:func:`swarmloc.protocol.session.session_config` calls for any config with TLS files, because
Zenoh itself only says "Unable to connect" for a missing, expired or foreign certificate.
"""

from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import json
import os
import sys
from collections.abc import Iterable
from pathlib import Path

#: The keys under ``transport/link/tls`` that name files.
FILE_KEYS = ("root_ca_certificate", "listen_certificate", "listen_private_key",
             "connect_certificate", "connect_private_key")
CA_NAME = "ca"
DEFAULT_HOSTS = ("localhost", "127.0.0.1")


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _write_private(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as handle:
        handle.write(data)


def _key_pem(key) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _cert_pem(cert) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return cert.public_bytes(serialization.Encoding.PEM)


def make_ca(folder: str | os.PathLike, common_name: str = "swarmloc CA", days: int = 3650) -> Path:
    """Write a new CA to ``folder/ca.pem`` and ``folder/ca-key.pem`` (mode 0600); return the
    certificate's path. Refuses to overwrite an existing CA (every certificate it signed would
    stop working)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cert_path, key_path = folder / f"{CA_NAME}.pem", folder / f"{CA_NAME}-key.pem"
    if cert_path.exists() or key_path.exists():
        raise ValueError(f"{cert_path}: a CA is already there (remove it to make a new one)")
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])
    now = _now()
    cert = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5)).not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                     content_commitment=False, key_encipherment=False,
                                     data_encipherment=False, key_agreement=False,
                                     encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    _write_private(key_path, _key_pem(key))
    cert_path.write_bytes(_cert_pem(cert))
    return cert_path


def issue(folder: str | os.PathLike, name: str, hosts: Iterable[str] = DEFAULT_HOSTS,
          days: float = 365.0, valid_from: dt.datetime | None = None) -> tuple[Path, Path]:
    """Sign a certificate for the piece ``name`` with the CA in ``folder``: ``folder/NAME.pem``
    and ``folder/NAME-key.pem`` (0600). Its common name is ``name`` (what an access-control
    subject's ``cert_common_names`` matches); ``hosts`` (names or IP addresses) are its subject
    alternative names, which a client checks against the host it connects to. It serves both
    as a server and a client certificate. ``valid_from`` (default now) and ``days`` set its
    validity (tests make expired ones)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    folder = Path(folder)
    if not name or "/" in name or name.startswith("."):
        raise ValueError(f"certificate name {name!r}: expected a plain file name such as 'robot-3'")
    ca_cert_path, ca_key_path = folder / f"{CA_NAME}.pem", folder / f"{CA_NAME}-key.pem"
    if not ca_key_path.exists():
        raise ValueError(f"{ca_key_path}: no CA here (make one with `swarmloc tls make-ca {folder}`)")
    ca_cert = x509.load_pem_x509_certificate(ca_cert_path.read_bytes())
    ca_key = serialization.load_pem_private_key(ca_key_path.read_bytes(), password=None)
    sans: list[x509.GeneralName] = []
    for host in hosts:
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            sans.append(x509.DNSName(host))
    key = ec.generate_private_key(ec.SECP256R1())
    start = valid_from or (_now() - dt.timedelta(minutes=5))
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca_cert.subject).public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start).not_valid_after(start + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                              ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
        .add_extension(x509.SubjectAlternativeName(sans), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
                       critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    cert_path, key_path = folder / f"{name}.pem", folder / f"{name}-key.pem"
    _write_private(key_path, _key_pem(key))
    cert_path.write_bytes(_cert_pem(cert))
    return cert_path, key_path


def tls_settings(ca: str | os.PathLike, cert: str | os.PathLike, key: str | os.PathLike,
                 *, listen: bool = False, mtls: bool = True) -> dict:
    """The ``transport/link/tls`` table for a piece: a router (``listen``) shows ``cert`` when
    clients connect; a client shows it to the router (mutual TLS)."""
    side = "listen" if listen else "connect"
    return {"root_ca_certificate": os.fspath(ca), f"{side}_certificate": os.fspath(cert),
            f"{side}_private_key": os.fspath(key), "enable_mtls": mtls,
            "close_link_on_expiration": True}


def apply_tls(config, ca, cert, key, *, listen: bool = False, mtls: bool = True):
    """Insert :func:`tls_settings` into a ``zenoh.Config``; returns it."""
    for k, v in tls_settings(ca, cert, key, listen=listen, mtls=mtls).items():
        config.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
    return config


def _load_cert(path: Path, what: str):
    from cryptography import x509

    if not path.is_file():
        raise ValueError(f"TLS {what} {path}: no such file")
    try:
        return x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError as exc:
        raise ValueError(f"TLS {what} {path}: not a PEM certificate ({exc})") from None


def _check_valid_now(cert, path: Path, what: str) -> None:
    now = _now()
    if cert.not_valid_after_utc < now:
        raise ValueError(f"TLS {what} {path}: expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC "
                         f"(issue a new one: swarmloc tls issue DIR NAME)")
    if cert.not_valid_before_utc > now:
        raise ValueError(f"TLS {what} {path}: not valid before "
                         f"{cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC (check this host's clock)")


def _check_signed_by(cert, ca, path: Path, ca_path: Path, what: str) -> None:
    from cryptography.exceptions import InvalidSignature

    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise ValueError(f"TLS {what} {path}: not signed by the CA {ca_path} (issued by "
                         f"'{cert.issuer.rfc4514_string()}'; issue it with this CA)") from None


def _check_key_matches(cert, key_path: Path, cert_path: Path, what: str) -> None:
    from cryptography.hazmat.primitives import serialization

    if not key_path.is_file():
        raise ValueError(f"TLS {what} private key {key_path}: no such file")
    try:
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"TLS {what} private key {key_path}: cannot read it ({exc})") from None
    pub = serialization.PublicFormat.SubjectPublicKeyInfo
    enc = serialization.Encoding.DER
    if key.public_key().public_bytes(enc, pub) != cert.public_key().public_bytes(enc, pub):
        raise ValueError(f"TLS {what} private key {key_path}: does not belong to {cert_path}")


def _check_certificate(cert_path: Path, key_path: Path, cas: list, ca_path: Path | None,
                       what: str) -> None:
    """``cert_path`` valid now, signed by one of ``cas`` (if any), its key ``key_path``."""
    cert = _load_cert(cert_path, what)
    _check_valid_now(cert, cert_path, what)
    for i, ca in enumerate(cas):
        try:
            _check_signed_by(cert, ca, cert_path, ca_path, what)
            break
        except ValueError:
            if i == len(cas) - 1:
                raise
    _check_key_matches(cert, key_path, cert_path, what)


def _load_cas(path: Path) -> list:
    """Every certificate of a CA file (one CA, or a bundle of several), each valid now."""
    from cryptography import x509

    _load_cert(path, "root CA certificate")  # names a missing or malformed file
    cas = x509.load_pem_x509_certificates(path.read_bytes())
    for ca in cas:
        _check_valid_now(ca, path, "root CA certificate")
    return cas


def check_files(ca_file: str | os.PathLike, cert_file: str | os.PathLike,
                key_file: str | os.PathLike) -> None:
    """ValueError naming the file and the problem unless ``ca_file`` holds CA certificates valid
    now (one, or a bundle) and ``cert_file`` is a certificate valid now, signed by one of them,
    whose private key is ``key_file``: the check of :func:`check_tls`, for other TLS users (the
    Dask executor)."""
    ca_path = Path(ca_file)
    _check_certificate(Path(cert_file), Path(key_file), _load_cas(ca_path), ca_path, "certificate")


def check_tls(config) -> None:
    """ValueError naming the file and the problem if the TLS files of a ``zenoh.Config`` are
    missing, unreadable, expired or not yet valid, not signed by its ``root_ca_certificate``,
    or if a private key does not belong to its certificate. A config without TLS files passes."""
    tls = json.loads(config.get_json("transport/link/tls"))
    files = {k: tls.get(k) for k in FILE_KEYS if tls.get(k)}
    if not files:
        return
    ca = ca_path = None
    if "root_ca_certificate" in files:
        ca_path = Path(files["root_ca_certificate"])
        ca = _load_cert(ca_path, "root CA certificate")
        _check_valid_now(ca, ca_path, "root CA certificate")
    for side in ("listen", "connect"):
        cert_file, key_file = files.get(f"{side}_certificate"), files.get(f"{side}_private_key")
        if cert_file is None and key_file is None:
            continue
        if cert_file is None or key_file is None:
            raise ValueError(f"TLS {side}: give both {side}_certificate and {side}_private_key")
        _check_certificate(Path(cert_file), Path(key_file), [ca] if ca is not None else [],
                           ca_path, f"{side} certificate")
    if tls.get("enable_mtls") and ca is None:
        raise ValueError("TLS: enable_mtls needs root_ca_certificate (the CA the peer's certificate "
                         "must be signed by)")


# -- command line -----------------------------------------------------------------------------


def main_tls(args) -> int:
    if args.tls_command == "make-ca":
        path = make_ca(args.dir, common_name=args.name, days=args.days)
        print(f"CA: {path} (key {path.with_name(CA_NAME + '-key.pem')}, keep it off the robots)")
    else:
        cert, key = issue(args.dir, args.name, hosts=args.host or DEFAULT_HOSTS, days=args.days)
        print(f"{args.name}: {cert} and {key}")
    return 0


def add_parser(subparsers) -> None:
    """Register ``swarmloc tls make-ca DIR`` and ``swarmloc tls issue DIR NAME``."""
    p = subparsers.add_parser("tls", help="make a CA and per-piece TLS certificates for tls/ endpoints")
    sub = p.add_subparsers(dest="tls_command", required=True)
    ca = sub.add_parser("make-ca", help="write DIR/ca.pem and DIR/ca-key.pem")
    ca.add_argument("dir")
    ca.add_argument("--name", default="swarmloc CA", help="the CA's common name")
    ca.add_argument("--days", type=int, default=3650)
    one = sub.add_parser("issue", help="write DIR/NAME.pem and DIR/NAME-key.pem, signed by DIR's CA")
    one.add_argument("dir")
    one.add_argument("name", help="the piece, e.g. router, world, robot-3, observer (its common name)")
    one.add_argument("--host", action="append", default=None,
                     help="host name or IP address the piece is reached at (repeatable; a router "
                          "needs the one clients connect to; default localhost and 127.0.0.1)")
    one.add_argument("--days", type=float, default=365.0)
    p.set_defaults(func=main_tls)


if __name__ == "__main__":  # pragma: no cover
    parser = argparse.ArgumentParser(prog="swarmloc-tls")
    add_parser(parser.add_subparsers(dest="command", required=True))
    ns = parser.parse_args()
    sys.exit(ns.func(ns))
