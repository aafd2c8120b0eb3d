// voxwarp._voxwarp: the Python binding of voxwarp's libraries (pybind11). The package voxwarp (voxwarp/__init__.py)
// re-exports it; see there and README.md ("Python") for the API. Frames and units as in the C++ headers: world
// units, voxel (i, j, k) centred at origin + voxel_size * (i, j, k).
#include <voxwarp/deform.h>
#include <voxwarp/errors.h>
#include <voxwarp/extract.h>
#include <voxwarp/mesh_io.h>
#include <voxwarp/voxelize.h>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <tbb/global_control.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <memory>
#include <mutex>

namespace py = pybind11;

namespace voxwarp::python {

namespace {

// ---- Exceptions: one Python class per C++ kind, with the C++ message. -------------------------------------------

struct ExceptionClasses {
    py::object error, invalid_input, resource_limit, solver_failure, io_error, cancelled;
};
ExceptionClasses& exceptions() {
    static ExceptionClasses classes;
    return classes;
}

py::object new_exception(py::module_& m, const char* name, py::tuple bases, const char* doc) {
    const std::string qualified = std::string("voxwarp.") + name;
    py::object cls = py::reinterpret_steal<py::object>(PyErr_NewExceptionWithDoc(qualified.c_str(), doc, bases.ptr(), nullptr));
    m.attr(name) = cls;
    return cls;
}

void register_exceptions(py::module_& m) {
    auto& e = exceptions();
    e.error = new_exception(m, "Error", py::make_tuple(py::handle(PyExc_RuntimeError)), "Base of every error voxwarp raises on purpose.");
    e.invalid_input = new_exception(m, "InvalidInput", py::make_tuple(e.error, py::handle(PyExc_ValueError)),
                                    "Malformed or out-of-range input: a file, an array, an edit (the CLI's exit code 2).");
    e.resource_limit = new_exception(m, "ResourceLimit", py::make_tuple(e.error, py::handle(PyExc_MemoryError)),
                                     "The request's memory estimate exceeds the limit; the message gives the estimate (exit code 3).");
    e.solver_failure = new_exception(m, "SolverFailure", py::make_tuple(e.error), "A numerical solve failed (exit code 4).");
    e.io_error = new_exception(m, "IOError", py::make_tuple(e.error, py::handle(PyExc_OSError)), "A file could not be read or written (exit code 5).");
    e.cancelled = new_exception(m, "Cancelled", py::make_tuple(e.error), "The progress callback asked to stop (exit code 6).");
    py::register_exception_translator([](std::exception_ptr p) {
        auto& x = exceptions();
        try {
            if (p) std::rethrow_exception(p);
        } catch (const InvalidInput& err) {
            PyErr_SetString(x.invalid_input.ptr(), err.what());
        } catch (const ResourceLimit& err) {
            PyErr_SetString(x.resource_limit.ptr(), err.what());
        } catch (const SolverFailure& err) {
            PyErr_SetString(x.solver_failure.ptr(), err.what());
        } catch (const IOError& err) {
            PyErr_SetString(x.io_error.ptr(), err.what());
        } catch (const Cancelled& err) {
            PyErr_SetString(x.cancelled.ptr(), err.what());
        } catch (const Error& err) {
            PyErr_SetString(x.error.ptr(), err.what());
        }
    });
}

// ---- Long calls: the GIL released, progress through a Python callback, Ctrl-C cancels. ---------------------------

std::atomic<bool> g_interrupted{false};
extern "C" void on_sigint(int) { g_interrupted = true; }

/// Runs a long C++ call with the GIL released. While it runs, SIGINT (Ctrl-C) only sets a flag that the progress
/// callback turns into a cancel (when called from the main thread: signal handlers are the process's), and the
/// user's callback, if any, is called with the GIL at most every 0.1 s. Afterwards an interrupted call raises
/// KeyboardInterrupt, a callback's own exception is re-raised, a callback that returned False raises Cancelled.
class LongCall {
public:
    explicit LongCall(py::object callback) : callback_(std::move(callback)) {
        const py::object threading = py::module_::import("threading");
        main_thread_ = threading.attr("current_thread")().is(threading.attr("main_thread")());
    }

    ProgressCallback progress() {
        return [this](std::string_view stage, double fraction) {
            if (g_interrupted) return false;
            if (callback_.is_none()) return true;
            const auto now = std::chrono::steady_clock::now();
            if (fraction < 1.0 && now - last_ < std::chrono::milliseconds(100)) return true;
            last_ = now;
            py::gil_scoped_acquire gil;
            try {
                const py::object answer = callback_(std::string(stage), fraction);
                return answer.is_none() || answer.cast<bool>();
            } catch (py::error_already_set& e) {
                std::lock_guard lock(mutex_);
                if (!error_) error_ = std::make_unique<py::error_already_set>(std::move(e));
                return false;
            }
        };
    }

    template <class F>
    auto run(F&& f) -> decltype(f()) {
        struct sigaction ours {}, previous{};
        ours.sa_handler = on_sigint;
        sigemptyset(&ours.sa_mask);
        if (main_thread_) {
            g_interrupted = false;
            sigaction(SIGINT, &ours, &previous);
        }
        auto restore = [&] {
            if (main_thread_) sigaction(SIGINT, &previous, nullptr);
        };
        try {
            decltype(f()) result = [&] {
                py::gil_scoped_release release;
                return f();
            }();
            restore();
            return result;
        } catch (const Cancelled&) {
            restore();
            if (main_thread_ && g_interrupted.exchange(false)) throw py::error_already_set(raise_keyboard_interrupt());
            if (error_) throw std::move(*error_);
            throw;
        } catch (...) {
            restore();
            throw;
        }
    }

private:
    static py::error_already_set raise_keyboard_interrupt() {
        PyErr_SetNone(PyExc_KeyboardInterrupt);
        return py::error_already_set();
    }
    py::object callback_;
    bool main_thread_ = false;
    std::chrono::steady_clock::time_point last_{};
    std::mutex mutex_;
    std::unique_ptr<py::error_already_set> error_;
};

// ---- Arrays in and out. -------------------------------------------------------------------------------------------

std::string shape_of(const py::array& a) {
    std::string s = "(";
    for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
    return s + (a.ndim() == 1 ? ",)" : ")");
}

/// V (n x 3 floats) and F (m x 3 integers) as a mesh, checked as the CLI checks a file (check_mesh).
TriangleMesh mesh_from_arrays(const py::handle& V_in, const py::handle& F_in) {
    const py::array V_any = py::array::ensure(V_in);
    const py::array F_any = py::array::ensure(F_in);
    if (!V_any || V_any.ndim() != 2 || V_any.shape(1) != 3)
        throw InvalidInput("V: expected an array of shape (n, 3), got " + (V_any ? "shape " + shape_of(V_any) : std::string("no array")));
    if (!F_any || F_any.ndim() != 2 || F_any.shape(1) != 3)
        throw InvalidInput("F: expected an array of shape (m, 3), got " + (F_any ? "shape " + shape_of(F_any) : std::string("no array")));
    const char kind_v = V_any.dtype().kind(), kind_f = F_any.dtype().kind();
    if (kind_v != 'f' && kind_v != 'i' && kind_v != 'u') throw InvalidInput("V: expected floating-point coordinates, got dtype " + std::string(py::str(V_any.dtype())));
    if (kind_f != 'i' && kind_f != 'u') throw InvalidInput("F: expected integer vertex indices, got dtype " + std::string(py::str(F_any.dtype())));
    const auto V = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(V_any);
    const auto F = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(F_any);
    TriangleMesh mesh;
    const auto v = V.unchecked<2>();
    const auto f = F.unchecked<2>();
    mesh.vertices.resize(std::size_t(V.shape(0)));
    for (py::ssize_t i = 0; i < V.shape(0); ++i) mesh.vertices[std::size_t(i)] = Eigen::Vector3d(v(i, 0), v(i, 1), v(i, 2));
    mesh.triangles.resize(std::size_t(F.shape(0)));
    const std::int64_t n = V.shape(0);
    for (py::ssize_t i = 0; i < F.shape(0); ++i)
        for (int c = 0; c < 3; ++c) {
            const std::int64_t index = f(i, c);
            if (index < 0 || index >= n)
                throw InvalidInput("F: face " + std::to_string(i) + " refers to vertex " + std::to_string(index) + ", the mesh has " + std::to_string(n) + " vertices");
            mesh.triangles[std::size_t(i)][std::size_t(c)] = std::int32_t(index);
        }
    check_mesh(mesh, "V");
    return mesh;
}

/// A vector's storage handed to numpy without a copy: the array owns it through a capsule.
template <class T, class Element>
py::array_t<T> adopt(std::vector<Element>&& data, py::ssize_t columns) {
    static_assert(sizeof(Element) % sizeof(T) == 0);
    auto* owned = new std::vector<Element>(std::move(data));
    const py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<Element>*>(p); });
    const py::ssize_t rows = py::ssize_t(owned->size() * sizeof(Element) / sizeof(T)) / columns;
    return py::array_t<T>({rows, columns}, {py::ssize_t(columns * sizeof(T)), py::ssize_t(sizeof(T))}, reinterpret_cast<const T*>(owned->data()), free_when_done);
}

py::tuple arrays_from_mesh(TriangleMesh&& mesh) {
    TriangleMesh triangles = mesh.quads.empty() ? std::move(mesh) : mesh.triangulated();
    static_assert(sizeof(Eigen::Vector3d) == 3 * sizeof(double) && sizeof(std::array<std::int32_t, 3>) == 3 * sizeof(std::int32_t));
    return py::make_tuple(adopt<double>(std::move(triangles.vertices), 3), adopt<std::int32_t>(std::move(triangles.triangles), 3));
}

/// A mesh's attributes as a dict of numpy arrays (the keys it has): "uv" float64 (k, 2), "uv_index" int32 (m, 3)
/// (each triangle's corners' rows of uv, -1: none), "normal" float64 (k, 3) and "normal_index" int32 (m, 3) likewise
/// (per-corner shading normals), "colour" float32 (n, 3) in [0, 1], "material" int32 (m,)
/// (index into "materials", -1: none), "materials": a list of dicts (name, diffuse, texture, statements), "group" int32
/// (m,) (index into "groups", -1: none), "groups": a list of names (OBJ's g and o).
py::dict attributes_dict(TriangleMesh& mesh) {
    static_assert(sizeof(Eigen::Vector2d) == 2 * sizeof(double) && sizeof(Eigen::Vector3f) == 3 * sizeof(float));
    py::dict a;
    if (!mesh.triangle_uvs.empty()) {
        a["uv"] = adopt<double>(std::move(mesh.uvs), 2);
        a["uv_index"] = adopt<std::int32_t>(std::move(mesh.triangle_uvs), 3);
    }
    if (!mesh.triangle_normals.empty()) {
        a["normal"] = adopt<double>(std::move(mesh.normals), 3);
        a["normal_index"] = adopt<std::int32_t>(std::move(mesh.triangle_normals), 3);
    }
    if (!mesh.colours.empty()) a["colour"] = adopt<float>(std::move(mesh.colours), 3);
    if (!mesh.triangle_materials.empty()) a["material"] = adopt<std::int32_t>(std::move(mesh.triangle_materials), 1).attr("reshape")(-1);
    py::list materials;
    for (const auto& m : mesh.materials)
        materials.append(py::dict(py::arg("name") = m.name, py::arg("diffuse") = py::make_tuple(m.diffuse.x(), m.diffuse.y(), m.diffuse.z()),
                                  py::arg("texture") = m.texture, py::arg("statements") = m.statements));
    if (!mesh.materials.empty()) a["materials"] = materials;
    if (!mesh.triangle_groups.empty()) {
        a["group"] = adopt<std::int32_t>(std::move(mesh.triangle_groups), 1).attr("reshape")(-1);
        a["groups"] = py::cast(mesh.groups);
    }
    return a;
}

/// The inverse of attributes_dict, checked against the mesh (sizes, indices, finite values); None: no attributes.
void attributes_from(const py::handle& attributes, TriangleMesh& mesh) {
    if (attributes.is_none()) return;
    if (!py::isinstance<py::dict>(attributes)) throw InvalidInput("attributes: expected a dict (the one read_mesh(..., attributes=True) returns)");
    const py::dict a = py::reinterpret_borrow<py::dict>(attributes);
    auto rows = [&](const char* key, py::ssize_t columns, auto type_tag) {
        using T = decltype(type_tag);
        const auto array = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(a[key]);
        const bool ok = array && (columns == 0 ? array.ndim() == 1 : array.ndim() == 2 && array.shape(1) == columns);
        if (!ok) throw InvalidInput(std::string("attributes[\"") + key + "\"]: expected an array of shape (k" + (columns ? ", " + std::to_string(columns) : std::string()) + ")");
        return array;
    };
    if (a.contains("uv") != a.contains("uv_index")) throw InvalidInput("attributes: \"uv\" and \"uv_index\" go together");
    if (a.contains("uv")) {
        const auto uv = rows("uv", 2, double{});
        const auto index = rows("uv_index", 3, std::int32_t{});
        for (py::ssize_t i = 0; i < uv.shape(0); ++i) mesh.uvs.emplace_back(uv.at(i, 0), uv.at(i, 1));
        for (py::ssize_t i = 0; i < index.shape(0); ++i) mesh.triangle_uvs.push_back({index.at(i, 0), index.at(i, 1), index.at(i, 2)});
    }
    if (a.contains("normal") != a.contains("normal_index")) throw InvalidInput("attributes: \"normal\" and \"normal_index\" go together");
    if (a.contains("normal")) {
        const auto normal = rows("normal", 3, double{});
        const auto index = rows("normal_index", 3, std::int32_t{});
        for (py::ssize_t i = 0; i < normal.shape(0); ++i) mesh.normals.emplace_back(normal.at(i, 0), normal.at(i, 1), normal.at(i, 2));
        for (py::ssize_t i = 0; i < index.shape(0); ++i) mesh.triangle_normals.push_back({index.at(i, 0), index.at(i, 1), index.at(i, 2)});
    }
    if (a.contains("colour")) {
        const auto c = rows("colour", 3, float{});
        for (py::ssize_t i = 0; i < c.shape(0); ++i) mesh.colours.emplace_back(c.at(i, 0), c.at(i, 1), c.at(i, 2));
    }
    if (a.contains("material")) {
        const auto m = rows("material", 0, std::int32_t{});
        for (py::ssize_t i = 0; i < m.shape(0); ++i) mesh.triangle_materials.push_back(m.at(i));
    }
    if (a.contains("group") != a.contains("groups")) throw InvalidInput("attributes: \"group\" and \"groups\" go together");
    if (a.contains("group")) {
        const auto g = rows("group", 0, std::int32_t{});
        for (py::ssize_t i = 0; i < g.shape(0); ++i) mesh.triangle_groups.push_back(g.at(i));
        mesh.groups = a["groups"].cast<std::vector<std::string>>();
    }
    if (a.contains("materials"))
        for (const auto& item : a["materials"]) {
            const py::dict d = py::reinterpret_borrow<py::dict>(item);
            Material m;
            m.name = d["name"].cast<std::string>();
            if (d.contains("diffuse")) {
                const auto k = d["diffuse"].cast<std::array<double, 3>>();
                m.diffuse = Eigen::Vector3d(k[0], k[1], k[2]);
            }
            if (d.contains("texture")) m.texture = d["texture"].cast<std::string>();
            if (d.contains("statements")) m.statements = d["statements"].cast<std::vector<std::string>>();
            mesh.materials.push_back(std::move(m));
        }
    check_attributes(mesh, "attributes");
}

/// An edit: a dict in the edit-file schema (validated by the same code, named "edit" in messages) or a path.
EditScript edit_from(const py::handle& edit) {
    if (py::isinstance<py::dict>(edit)) {
        const std::string text = py::module_::import("json").attr("dumps")(edit).cast<std::string>();
        return parse_edit_script(text, "edit");
    }
    if (py::isinstance<py::str>(edit) || py::hasattr(edit, "__fspath__")) return read_edit_file(py::str(py::module_::import("os").attr("fspath")(edit)));
    throw InvalidInput("edit: expected a dict in the edit-file schema or a path to an edit file, got " + std::string(py::str(py::type::of(edit).attr("__name__"))));
}

py::object report_dict(const DeformReport& report) { return py::module_::import("json").attr("loads")(report_json(report)); }

std::string path_of(const py::handle& p) { return py::str(py::module_::import("os").attr("fspath")(p)); }

// ---- The Voxmap class: a dense voxmap whose density numpy views without a copy. ------------------------------------

py::array_t<float> density_view(const std::shared_ptr<Voxmap>& v, py::handle owner) {
    const auto& n = v->dims;
    const py::ssize_t s = sizeof(float);
    // density[i, j, k] is voxel (i, j, k): x fastest in memory (Fortran order), as the C++ Voxmap stores it.
    return py::array_t<float>({py::ssize_t(n[0]), py::ssize_t(n[1]), py::ssize_t(n[2])}, {s, s * py::ssize_t(n[0]), s * py::ssize_t(n[0] * n[1])}, v->density.data(),
                              owner);
}

std::shared_ptr<Voxmap> voxmap_from_array(const py::handle& density_in, const py::handle& origin_in, double voxel_size) {
    const auto density = py::array_t<float, py::array::f_style | py::array::forcecast>::ensure(density_in);
    if (!density || density.ndim() != 3)
        throw InvalidInput("density: expected an array of shape (nx, ny, nz), got " + (density ? "shape " + shape_of(density) : std::string("no array")));
    const auto origin = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(origin_in);
    if (!origin || origin.size() != 3) throw InvalidInput("origin: expected three numbers");
    if (!(voxel_size > 0) || !std::isfinite(voxel_size)) throw InvalidInput("voxel_size: expected a finite number > 0, got " + std::to_string(voxel_size));
    auto v = std::make_shared<Voxmap>();
    v->dims = {density.shape(0), density.shape(1), density.shape(2)};
    if (v->voxel_count() == 0) throw InvalidInput("density: the array is empty");
    v->origin = Eigen::Vector3d(origin.at(0), origin.at(1), origin.at(2));
    if (!v->origin.allFinite()) throw InvalidInput("origin: not finite");
    v->voxel_size = voxel_size;
    v->density.assign(density.data(), density.data() + v->voxel_count());
    for (float x : v->density)
        if (!std::isfinite(x)) throw InvalidInput("density: holds non-finite values (NaN or infinity)");
    return v;
}

VoxelizeOptions voxelize_options(int resolution, const py::object& voxel_size, int padding, const std::string& sign, const py::object& max_memory) {
    VoxelizeOptions o;
    o.resolution = resolution;
    if (!voxel_size.is_none()) o.voxel_size = voxel_size.cast<double>();
    o.padding_voxels = padding;
    o.sign = parse_sign(sign);
    if (!max_memory.is_none()) o.max_memory_bytes = std::uint64_t(max_memory.cast<double>() * double(1ull << 30));
    return o;
}

} // namespace

void define_module(py::module_& m) {
    m.doc() = "voxwarp's C++ libraries: mesh I/O, voxelize, extract, deform (see the package voxwarp)";
    register_exceptions(m);

    m.def(
        "read_mesh",
        [](const py::handle& path, bool attributes) -> py::tuple {
            const std::string p = path_of(path);
            TriangleMesh mesh;
            std::vector<std::string> warnings;
            {
                py::gil_scoped_release release;
                mesh = read_mesh(p, &warnings);
            }
            for (const auto& w : warnings) PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1);
            if (!attributes) return arrays_from_mesh(std::move(mesh));
            py::dict a = attributes_dict(mesh);
            py::tuple arrays = arrays_from_mesh(std::move(mesh));
            return py::make_tuple(arrays[0], arrays[1], a);
        },
        py::arg("path"), py::kw_only(), py::arg("attributes") = false,
        "Read a mesh file (.obj .off .ply .stl .om .gltf .glb) as (V, F): float64 (n, 3) world positions, int32 (m, 3) triangles;\n"
        "with attributes=True, (V, F, attributes): texture coordinates, colours, materials and groups as a dict of arrays. A missing\n"
        ".mtl or texture is a UserWarning.");
    m.def(
        "write_mesh",
        [](const py::handle& path, const py::handle& V, const py::handle& F, const py::handle& attributes) {
            const std::string p = path_of(path);
            TriangleMesh mesh = mesh_from_arrays(V, F);
            attributes_from(attributes, mesh);
            py::gil_scoped_release release;
            write_mesh(mesh, p);
        },
        py::arg("path"), py::arg("V"), py::arg("F"), py::arg("attributes") = py::none(),
        "Write (V, F) to a mesh file (format by extension), atomically: a failure leaves no file. `attributes` as read_mesh\n"
        "gives them (an OBJ with materials gets its .mtl beside it).");

    py::class_<Voxmap, std::shared_ptr<Voxmap>>(m, "Voxmap", "A dense density volume: density in [0, 1], surface at 0.5.")
        .def(py::init([](const py::handle& density, const py::handle& origin, double voxel_size) { return voxmap_from_array(density, origin, voxel_size); }),
             py::arg("density"), py::arg("origin") = py::make_tuple(0.0, 0.0, 0.0), py::arg("voxel_size") = 1.0,
             "From a (nx, ny, nz) array (copied); voxel (i, j, k) is centred at origin + voxel_size * (i, j, k).")
        .def_property_readonly(
            "density", [](py::object self) { return density_view(self.cast<std::shared_ptr<Voxmap>>(), self); },
            "float32 (nx, ny, nz) view of the densities (no copy): density[i, j, k] is voxel (i, j, k).")
        .def_property_readonly("origin", [](const Voxmap& v) { return py::make_tuple(v.origin.x(), v.origin.y(), v.origin.z()); },
                               "World position of voxel (0, 0, 0)'s centre.")
        .def_property_readonly("voxel_size", [](const Voxmap& v) { return v.voxel_size; }, "Voxel size, world units.")
        .def_property_readonly("dims", [](const Voxmap& v) { return py::make_tuple(v.dims[0], v.dims[1], v.dims[2]); }, "(nx, ny, nz).")
        .def("enclosed_volume", [](const Voxmap& v) { return enclosed_volume(v); }, "Volume inside the 0.5 isosurface, world units cubed.")
        .def("__repr__", [](const Voxmap& v) {
            return "<voxwarp.Voxmap " + std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" + std::to_string(v.dims[2]) + ", voxel size " +
                   std::to_string(v.voxel_size) + ">";
        });

    m.def(
        "voxelize",
        [](const py::handle& V, const py::handle& F, int resolution, const py::object& voxel_size, int padding, const std::string& sign, const py::object& max_memory,
           const py::object& progress) {
            const TriangleMesh mesh = mesh_from_arrays(V, F);
            VoxelizeOptions o = voxelize_options(resolution, voxel_size, padding, sign, max_memory);
            LongCall call(progress);
            o.progress = call.progress();
            return call.run([&] { return std::make_shared<Voxmap>(voxelize(mesh, o)); });
        },
        py::arg("V"), py::arg("F"), py::kw_only(), py::arg("resolution") = 128, py::arg("voxel_size") = py::none(), py::arg("padding") = 3,
        py::arg("sign") = "auto", py::arg("max_memory") = py::none(), py::arg("progress") = py::none(),
        "Voxelize a mesh into a Voxmap: `resolution` voxels along its longest side, or `voxel_size` world units.");
    m.def(
        "extract",
        [](const std::shared_ptr<Voxmap>& voxmap, double isovalue, double adaptivity, const std::string& mesher, const py::object& progress) {
            ExtractOptions o;
            o.isovalue = isovalue, o.adaptivity = adaptivity, o.mesher = parse_mesher(mesher);
            LongCall call(progress);
            o.progress = call.progress();
            return arrays_from_mesh(call.run([&] { return extract(*voxmap, o); }));
        },
        py::arg("voxmap"), py::kw_only(), py::arg("isovalue") = 0.5, py::arg("adaptivity") = 0.0, py::arg("mesher") = "mc", py::arg("progress") = py::none(),
        "The isosurface of a Voxmap as (V, F): a closed, outward-wound triangle mesh.");
    m.def(
        "deform",
        [](const py::handle& V, const py::handle& F, const py::handle& edit, int resolution, const py::object& voxel_size, const std::string& mode, bool preview,
           int max_steps, std::size_t faces, const std::string& mesher, const std::string& sign, bool snap, const py::object& attributes,
           const py::object& max_memory, const py::object& progress) -> py::tuple {
            TriangleMesh mesh = mesh_from_arrays(V, F);
            attributes_from(attributes, mesh);
            const EditScript script = edit_from(edit);
            if (mode != "volume" && mode != "vertex") throw InvalidInput("mode: expected \"volume\" or \"vertex\", got \"" + mode + "\"");
            if (max_steps < 1 || max_steps > 64) throw InvalidInput("max_steps: " + std::to_string(max_steps) + " is outside [1, 64]");
            DeformOptions o;
            o.voxelize = voxelize_options(resolution, voxel_size, 3, sign, max_memory);
            o.preview = preview, o.max_steps = max_steps, o.target_faces = faces, o.snap = snap;
            o.extract.mesher = parse_mesher(mesher);
            LongCall call(progress);
            o.progress = call.progress();
            DeformReport report;
            const auto start = std::chrono::steady_clock::now();
            TriangleMesh out = call.run([&] { return mode == "vertex" ? deform_vertices(mesh, script, o, report) : deform_mesh(mesh, script, o, report); });
            report.seconds_total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            py::dict a = attributes_dict(out);
            py::tuple arrays = arrays_from_mesh(std::move(out));
            if (attributes.is_none()) return py::make_tuple(arrays[0], arrays[1], report_dict(report));
            return py::make_tuple(arrays[0], arrays[1], report_dict(report), a);
        },
        py::arg("V"), py::arg("F"), py::arg("edit"), py::kw_only(), py::arg("resolution") = 128, py::arg("voxel_size") = py::none(), py::arg("mode") = "volume",
        py::arg("preview") = false, py::arg("max_steps") = 8, py::arg("faces") = 0, py::arg("mesher") = "mc", py::arg("sign") = "auto", py::arg("snap") = true,
        py::arg("attributes") = py::none(), py::arg("max_memory") = py::none(), py::arg("progress") = py::none(),
        "Deform a mesh by an edit script (dict or path): voxelize, warp, re-polygonize, and (snap=True) move each output vertex onto\n"
        "the exact image of its source point on the input. Returns (V, F, report); given the input's `attributes` (as read_mesh\n"
        "returns them), (V, F, report, attributes) with the output's, read at each vertex's source point.");
    m.def(
        "set_threads",
        [](int threads) {
            static std::unique_ptr<tbb::global_control> limit;
            if (threads < 0 || threads > 4096) throw InvalidInput("threads: " + std::to_string(threads) + " is outside [0, 4096]");
            limit.reset();
            if (threads > 0) limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        },
        py::arg("threads"), "Most worker threads voxwarp's calls use from now on (0: all cores). Results do not depend on it.");
    m.def(
        "read_edit",
        [](const py::handle& edit) {
            const EditScript s = edit_from(edit);
            return s.edits.size();
        },
        py::arg("edit"), "Validate an edit (dict or path) as deform would; returns the number of edits.");
}

} // namespace voxwarp::python

PYBIND11_MODULE(_voxwarp, m) { voxwarp::python::define_module(m); }
