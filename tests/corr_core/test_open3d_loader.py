"""corr_core.open3d_loader: Open3D importable without a system libusb, its plotly drawing imported only when used."""
import subprocess
import sys
import textwrap


def _in_fresh_interpreter(code: str) -> str:
    """stdout of ``code`` run by a new Python process (the modules this test process imported do not count)."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_open3d_loads_without_plotly_and_dash_until_its_plotly_drawing_is_called():
    out = _in_fresh_interpreter("""
        import sys
        from corr_core.open3d_loader import load_open3d
        o3d = load_open3d()
        print(sorted(m for m in ("dash", "plotly", "IPython") if m in sys.modules))
        mesh = o3d.geometry.TriangleMesh.create_box()
        scene = o3d.t.geometry.RaycastingScene()           # the rendering the project does works as before
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
        print(type(o3d.visualization.get_plotly_fig([mesh])).__module__.split(".")[0])
        print("dash" in sys.modules, o3d.visualization.draw_plotly.__module__)
    """).splitlines()
    assert out[0] == "[]"                                    # nothing of plotly/dash/IPython imported by open3d
    assert out[1] == "plotly"                                # the real plotly drawing on the first call
    assert out[2] == "True open3d.visualization.draw_plotly"  # ... and the package holds the real functions after
