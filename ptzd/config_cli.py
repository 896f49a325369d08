"""`ptzd check-config FILE`: validate a config and print the effective result."""

from __future__ import annotations

import argparse
import os
import stat
import sys
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ptzd.config import Config


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    parser = subparsers.add_parser(
        "check-config",
        help="validate a config file and print the effective config",
        description="Validate FILE (with PTZD_SECTION__KEY environment overrides applied). "
        "Prints every error with its key path and value and exits 2, "
        "or prints the effective config as TOML and exits 0.",
    )
    parser.add_argument("file", help="TOML config file")
    parser.set_defaults(handler=_check_config)


def _check_config(args: argparse.Namespace) -> int:
    from ptzd.config import load_config, to_toml

    config = load_config(args.file)  # ConfigError -> printed and exit 2 by the CLI
    print(to_toml(config), end="")
    for warning in secret_file_warnings(config, Path(args.file), os.environ):
        print(f"ptzd: warning: {warning}", file=sys.stderr)
    return 0


def secret_file_warnings(config: Config, path: Path, environ: Mapping[str, str]) -> list[str]:
    """Files holding a secret that any local user can read: the MQTT client key, the
    systemd password credential, and the config file itself when it sets `mqtt.password`."""
    secrets: list[tuple[str, Path]] = []
    if config.mqtt.key_file is not None:
        secrets.append(("mqtt.key_file", config.mqtt.key_file))
    if environ.get("CREDENTIALS_DIRECTORY"):
        credential = Path(environ["CREDENTIALS_DIRECTORY"]) / config.mqtt.password_credential
        secrets.append(("mqtt.password_credential", credential))
    try:
        if "password" in tomllib.loads(path.read_text(encoding="utf-8")).get("mqtt", {}):
            secrets.append(("mqtt.password", path))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, AttributeError):
        pass  # load_config already accepted it; nothing more to learn here
    warnings = []
    for key, secret in secrets:
        try:
            mode = secret.stat().st_mode
        except OSError:
            continue  # missing files are reported where they are opened
        if mode & stat.S_IROTH:
            warnings.append(
                f"{key}: {secret} is world-readable (mode {stat.S_IMODE(mode):04o}); "
                f"run chmod o-rwx {secret}"
            )
    return warnings
