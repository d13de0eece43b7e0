"""Build hook: the top-level ``configs/`` (devices, dataset presets, training recipes) goes into
the wheel as ``physics/configs/``, where :func:`physics.device.config_dir` finds it; an editable
install or a checkout reads the top-level folder itself.  Everything else is in pyproject.toml."""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


class BuildWithConfigs(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        target = Path(self.build_lib) / "physics" / "configs"
        shutil.rmtree(target, ignore_errors=True)
        for src in sorted((ROOT / "configs").rglob("*.yaml")):
            dst = target / src.relative_to(ROOT / "configs")
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, dst)


setup(cmdclass={"build_py": BuildWithConfigs})
