#include "store/hdf5_export.hpp"

#include <hdf5.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include "base/user_error.hpp"

namespace manikind {
namespace {

// Once per process, before the first HDF5 call: errors become UserErrors, not stderr dumps; and
// no library clean-up at exit. A file whose write failed (a full disk) stays open inside HDF5
// 1.10, and its exit handler then flushes it again and crashes (rc 139 after the right error
// message); every file we keep is closed explicitly and checked, so nothing is lost by skipping it.
void library_setup() {
    static const bool done = [] {
        H5dont_atexit();
        return true;
    }();
    (void)done;
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // per thread where the library is thread-safe
}

// One HDF5 identifier, closed with the function of its kind.
class Handle {
public:
    Handle(hid_t id, herr_t (*closer)(hid_t)) : id_(id), close_(closer) {}
    Handle(Handle&& other) noexcept : id_(other.id_), close_(other.close_) { other.id_ = -1; }
    Handle(const Handle&) = delete;
    Handle& operator=(const Handle&) = delete;
    Handle& operator=(Handle&&) = delete;
    ~Handle() {
        if (id_ >= 0) close_(id_);
    }
    hid_t get() const { return id_; }
    bool ok() const { return id_ >= 0; }
    // Closes now and says whether it worked (a file's close writes what is still buffered).
    bool close() {
        const hid_t id = id_;
        id_ = -1;
        return id < 0 || close_(id) >= 0;
    }

private:
    hid_t id_;
    herr_t (*close_)(hid_t);
};

class Writer {
public:
    explicit Writer(const std::filesystem::path& path) : path_(path), file_(create(path), H5Fclose) {}

    hid_t root() const { return file_.get(); }

    Handle group(hid_t parent, const std::string& name) {
        Handle g(H5Gcreate2(parent, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
        check(g.ok(), "creating group " + name);
        return g;
    }

    template <typename T>
    void dataset(hid_t parent, const std::string& name, const std::vector<T>& values, hid_t memory_type,
                 const std::string& unit = {}) {
        const hsize_t dims[1] = {values.size()};
        Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose);
        Handle set(H5Dcreate2(parent, name.c_str(), memory_type, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                   H5Dclose);
        check(set.ok(), "creating dataset " + name);
        if (!values.empty())
            check(H5Dwrite(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) >= 0, "writing " + name);
        if (!unit.empty()) attribute(set.get(), "unit", unit);
    }

    // A scalar fixed-length string dataset (Octave's load reads it as char; it does not read
    // variable-length strings).
    void string_dataset(hid_t parent, const std::string& name, const std::string& text) {
        Handle type(fixed_string_type(text.size()), H5Tclose);
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle set(H5Dcreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                   H5Dclose);
        check(set.ok(), "creating dataset " + name);
        check(H5Dwrite(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, text.data()) >= 0, "writing " + name);
    }

    // Fixed-length strings, one per element, padded with NUL (a char matrix in Octave).
    void strings_dataset(hid_t parent, const std::string& name, const std::vector<std::string>& texts) {
        std::size_t width = 1;
        for (const auto& t : texts) width = std::max(width, t.size());
        std::vector<char> packed(texts.size() * width, '\0');
        for (std::size_t i = 0; i < texts.size(); ++i) std::copy(texts[i].begin(), texts[i].end(), packed.begin() + static_cast<long>(i * width));
        Handle type(fixed_string_type(width), H5Tclose);
        const hsize_t dims[1] = {texts.size()};
        Handle space(H5Screate_simple(1, dims, nullptr), H5Sclose);
        Handle set(H5Dcreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                   H5Dclose);
        check(set.ok(), "creating dataset " + name);
        if (texts.empty()) return;  // an empty column: created, nothing to write
        check(H5Dwrite(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, packed.data()) >= 0, "writing " + name);
    }

    // Variable-length UTF-8: h5py gives str (a fixed-length one reads as bytes), MATLAB's
    // h5readatt a char row; Octave's load skips attributes whatever their type.
    void attribute(hid_t object, const std::string& name, const std::string& text) {
        Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
        H5Tset_size(type.get(), H5T_VARIABLE);
        H5Tset_cset(type.get(), H5T_CSET_UTF8);
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle attr(H5Acreate2(object, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
        check(attr.ok(), "creating attribute " + name);
        const char* data = text.c_str();
        check(H5Awrite(attr.get(), type.get(), &data) >= 0, "writing attribute " + name);
    }

    void attribute(hid_t object, const std::string& name, double value) {
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle attr(H5Acreate2(object, name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
        check(attr.ok(), "creating attribute " + name);
        check(H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, &value) >= 0, "writing attribute " + name);
    }

    void attribute(hid_t object, const std::string& name, std::int64_t value) {
        Handle space(H5Screate(H5S_SCALAR), H5Sclose);
        Handle attr(H5Acreate2(object, name.c_str(), H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
        check(attr.ok(), "creating attribute " + name);
        check(H5Awrite(attr.get(), H5T_NATIVE_INT64, &value) >= 0, "writing attribute " + name);
    }

    void check(bool ok, const std::string& what) const {
        if (!ok) {
            const int err = errno;  // HDF5's own stack says only "write failed"; the system says why
            throw UserError(fmt::format("{}: HDF5 failed {}{}", path_.string(), what,
                                        err != 0 ? fmt::format(" ({})", std::strerror(err)) : std::string()),
                            "write_failed");
        }
    }
    void close() { check(file_.close(), "closing the file"); }

private:
    static hid_t create(const std::filesystem::path& path) {
        library_setup();
        errno = 0;
        const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
        if (f < 0) throw UserError(fmt::format("{}: cannot create the HDF5 file", path.string()));
        return f;
    }
    // Labelled ASCII although the bytes are UTF-8 (°, ²): Octave 7's load refuses a dataset
    // whose character set is UTF-8, and passes the bytes through unchanged either way.
    static hid_t fixed_string_type(std::size_t size) {
        const hid_t t = H5Tcopy(H5T_C_S1);
        H5Tset_size(t, std::max<std::size_t>(size, 1));
        H5Tset_strpad(t, H5T_STR_NULLPAD);
        return t;
    }

    std::filesystem::path path_;
    Handle file_;
};

// Results per case in columns: what a script plots without parsing JSON.
void write_results(Writer& w, hid_t parent, const nlohmann::json& analysis) {
    Handle results = w.group(parent, "results");
    w.string_dataset(results.get(), "analysis_json", analysis.dump());
    std::vector<std::int32_t> case_ids, n;
    std::vector<double> q, u95, k, u_a, u_b;
    const auto number = [](const nlohmann::json& j, const char* key) {
        return j.contains(key) && j.at(key).is_number() ? j.at(key).get<double>() : std::numeric_limits<double>::quiet_NaN();
    };
    for (const auto& c : analysis.value("cases", nlohmann::json::array())) {
        case_ids.push_back(c.value("case", 0));
        const auto& wb = c.value("whole_body", nlohmann::json::object());
        n.push_back(c.value("n_replicates", 0));
        q.push_back(number(wb, "q_w_m2"));
        u95.push_back(number(wb, "U"));
        k.push_back(number(wb, "k"));
        u_a.push_back(number(wb, "u_a"));
        u_b.push_back(number(wb, "u_b"));
    }
    w.dataset(results.get(), "case", case_ids, H5T_NATIVE_INT32);
    w.dataset(results.get(), "n_replicates", n, H5T_NATIVE_INT32);
    w.dataset(results.get(), "q_wb_w_m2", q, H5T_NATIVE_DOUBLE, "W/m²");
    w.dataset(results.get(), "u95_w_m2", u95, H5T_NATIVE_DOUBLE, "W/m²");
    w.dataset(results.get(), "k", k, H5T_NATIVE_DOUBLE, "1");
    w.dataset(results.get(), "u_a_w_m2", u_a, H5T_NATIVE_DOUBLE, "W/m²");
    w.dataset(results.get(), "u_b_w_m2", u_b, H5T_NATIVE_DOUBLE, "W/m²");
    w.attribute(results.get(), "heat_flux_sign", std::string(analysis::kHeatFluxSign));
}

void write_file(const std::filesystem::path& path, const analysis::Campaign& c, const nlohmann::json& analysis_json) {
    Writer w(path);
    w.attribute(w.root(), "format", std::string(kHdf5Format));
    w.attribute(w.root(), "campaign", c.name);
    w.attribute(w.root(), "heat_flux_sign", std::string(analysis::kHeatFluxSign));
    for (const auto& [key, value] : c.provenance) w.attribute(w.root(), key, value);

    {
        Handle zones = w.group(w.root(), "zone_map");
        std::vector<std::int32_t> number;
        std::vector<double> area;
        std::vector<std::string> names, regions;
        for (const auto& z : c.zone_map.zones) {
            number.push_back(z.zone);
            area.push_back(z.area_m2);
            names.push_back(z.name);
            regions.push_back(z.region);
        }
        w.dataset(zones.get(), "zone", number, H5T_NATIVE_INT32);
        w.dataset(zones.get(), "area_m2", area, H5T_NATIVE_DOUBLE, "m²");
        w.strings_dataset(zones.get(), "name", names);
        w.strings_dataset(zones.get(), "region", regions);
    }

    // The lab notebook: one row per note, in time order, as parallel string columns (trial empty:
    // about the campaign); written even when empty, so a script need not test for the group.
    {
        Handle notes = w.group(w.root(), "notes");
        std::vector<std::string> utc, author, kind, text, trial;
        for (const auto& n : c.notes) {
            utc.push_back(analysis::iso_utc_ms(n.utc_ns));
            author.push_back(n.author);
            kind.push_back(n.kind);
            text.push_back(n.text);
            trial.push_back(n.trial);
        }
        w.strings_dataset(notes.get(), "utc", utc);
        w.strings_dataset(notes.get(), "author", author);
        w.strings_dataset(notes.get(), "kind", kind);
        w.strings_dataset(notes.get(), "text", text);
        w.strings_dataset(notes.get(), "trial", trial);
    }

    Handle trials = w.group(w.root(), "trials");
    const auto columns_of = [&](const analysis::TrialData& d) {
        return analysis::trial_csv_columns(c.zone_map, !d.air_speed_m_s.empty(), !d.wall_temp_c.empty());
    };
    for (const auto& t : c.trials) {
        const auto& d = t.data;
        Handle g = w.group(trials.get(), t.info.id);
        w.attribute(g.get(), "case", static_cast<std::int64_t>(t.info.case_id));
        w.attribute(g.get(), "replicate", static_cast<std::int64_t>(t.info.replicate));
        if (t.info.skin_setpoint_c) w.attribute(g.get(), "skin_setpoint_c", *t.info.skin_setpoint_c);
        if (t.info.wettedness) w.attribute(g.get(), "wettedness", *t.info.wettedness);
        // The chamber's setpoints beside the enclosure's readings (a trial group says what was asked).
        if (t.info.chamber_setpoint_temp_c) w.attribute(g.get(), "chamber_setpoint_temp_c", *t.info.chamber_setpoint_temp_c);
        if (t.info.chamber_setpoint_rh_pct) w.attribute(g.get(), "chamber_setpoint_rh_pct", *t.info.chamber_setpoint_rh_pct);
        if (!t.info.ensemble.empty()) w.attribute(g.get(), "ensemble", t.info.ensemble);
        if (!t.info.test.empty()) w.attribute(g.get(), "test", t.info.test);
        if (!t.info.control.empty()) w.attribute(g.get(), "control", t.info.control);
        if (t.info.partial) w.attribute(g.get(), "partial", std::int64_t{1});  // exported while running
        if (t.info.t0_utc_ns) w.attribute(g.get(), "t0_utc", analysis::iso_utc_ms(*t.info.t0_utc_ns));
        w.dataset(g.get(), "t_s", d.t_s, H5T_NATIVE_DOUBLE, "s");
        if (!d.utc_ns.empty()) w.dataset(g.get(), "utc_ns", d.utc_ns, H5T_NATIVE_INT64, "ns since 1970-01-01T00:00:00Z");
        // The analysis columns, named as in the CSV.
        std::vector<const std::vector<double>*> series{&d.air_temp_c, &d.air_rh_pct};
        std::vector<std::string> units{"°C", "%"};
        if (!d.air_speed_m_s.empty()) series.push_back(&d.air_speed_m_s), units.emplace_back("m/s");
        if (!d.wall_temp_c.empty()) series.push_back(&d.wall_temp_c), units.emplace_back("°C");
        for (const auto& z : d.skin_temp_c) series.push_back(&z), units.emplace_back("°C");
        for (const auto& z : d.heat_flux_w_m2) series.push_back(&z), units.emplace_back("W/m²");
        const auto names = columns_of(d);
        for (std::size_t i = 0; i < series.size(); ++i) w.dataset(g.get(), names[i + 1], *series[i], H5T_NATIVE_DOUBLE, units[i]);
        for (std::size_t k = 0; k < c.channels.size() && k < d.channel_values.size(); ++k) {
            const auto& ch = c.channels[k];
            w.dataset(g.get(), ch.column(), d.channel_values[k], H5T_NATIVE_DOUBLE, ch.unit);
            w.dataset(g.get(), ch.column() + ".q", d.channel_quality[k], H5T_NATIVE_UINT8,
                      "quality: 0 good, 1 stale, 2 out of range, 3 communication error, 255 no sample");
        }
    }
    write_results(w, w.root(), analysis_json);
    w.check(H5Fflush(w.root(), H5F_SCOPE_GLOBAL) >= 0, "flushing");
    w.close();
}

// Opens `file` read-only and one dataset in it.
struct DatasetReader {
    Handle file;
    Handle set;
    DatasetReader(const std::filesystem::path& path, const std::string& name)
        : file((library_setup(), H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT)), H5Fclose),
          set(file.ok() ? H5Dopen2(file.get(), name.c_str(), H5P_DEFAULT) : -1, H5Dclose) {
        if (!file.ok()) throw UserError(fmt::format("{}: not an HDF5 file, or unreadable", path.string()));
        if (!set.ok()) throw UserError(fmt::format("{}: no dataset '{}'", path.string(), name));
    }
    std::size_t size() const {
        Handle space(H5Dget_space(set.get()), H5Sclose);
        const auto n = H5Sget_simple_extent_npoints(space.get());
        return n < 0 ? 0 : static_cast<std::size_t>(n);
    }
    template <typename T>
    std::vector<T> read(hid_t memory_type, const std::filesystem::path& path, const std::string& name) const {
        std::vector<T> out(size());
        if (!out.empty() && H5Dread(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
            throw UserError(fmt::format("{}: cannot read '{}' as the requested type", path.string(), name));
        return out;
    }
};

}  // namespace

void write_campaign_hdf5(const std::filesystem::path& file, const analysis::Campaign& campaign,
                         const nlohmann::json& analysis_json) {
    const std::filesystem::path partial = file.string() + fmt::format(".partial-{}", ::getpid());
    try {
        write_file(partial, campaign, analysis_json);
    } catch (...) {
        std::error_code ignored;
        std::filesystem::remove(partial, ignored);
        throw;
    }
    std::filesystem::rename(partial, file);
}

std::vector<double> hdf5_read_doubles(const std::filesystem::path& file, const std::string& dataset) {
    return DatasetReader(file, dataset).read<double>(H5T_NATIVE_DOUBLE, file, dataset);
}

std::vector<std::int64_t> hdf5_read_int64(const std::filesystem::path& file, const std::string& dataset) {
    return DatasetReader(file, dataset).read<std::int64_t>(H5T_NATIVE_INT64, file, dataset);
}

std::vector<std::uint8_t> hdf5_read_uint8(const std::filesystem::path& file, const std::string& dataset) {
    return DatasetReader(file, dataset).read<std::uint8_t>(H5T_NATIVE_UINT8, file, dataset);
}

std::string hdf5_read_string(const std::filesystem::path& file, const std::string& dataset) {
    const DatasetReader r(file, dataset);
    Handle type(H5Dget_type(r.set.get()), H5Tclose);
    if (H5Tget_class(type.get()) != H5T_STRING || H5Tis_variable_str(type.get()) > 0)
        throw UserError(fmt::format("{}: '{}' is not a fixed-length string", file.string(), dataset));
    std::string out(H5Tget_size(type.get()), '\0');
    if (H5Dread(r.set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
        throw UserError(fmt::format("{}: cannot read '{}'", file.string(), dataset));
    if (const auto nul = out.find('\0'); nul != std::string::npos) out.resize(nul);
    return out;
}

std::string hdf5_read_string_attribute(const std::filesystem::path& file, const std::string& object,
                                       const std::string& attribute) {
    library_setup();
    Handle f(H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
    if (!f.ok()) throw UserError(fmt::format("{}: not an HDF5 file, or unreadable", file.string()));
    Handle attr(H5Aopen_by_name(f.get(), object.c_str(), attribute.c_str(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
    if (!attr.ok()) throw UserError(fmt::format("{}: no attribute '{}' on '{}'", file.string(), attribute, object));
    Handle type(H5Aget_type(attr.get()), H5Tclose);
    if (H5Tget_class(type.get()) != H5T_STRING || H5Tis_variable_str(type.get()) <= 0)
        throw UserError(fmt::format("{}: attribute '{}' is not a variable-length string", file.string(), attribute));
    char* text = nullptr;
    if (H5Aread(attr.get(), type.get(), &text) < 0 || !text)
        throw UserError(fmt::format("{}: cannot read attribute '{}'", file.string(), attribute));
    std::string out(text);
    H5free_memory(text);
    return out;
}

}  // namespace manikind
