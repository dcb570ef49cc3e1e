#include "store/hdf5_export.hpp"

#include <hdf5.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <streambuf>

#include <fmt/format.h>

#include "analysis/analyze.hpp"
#include "base/lazy_library.hpp"
#include "base/user_error.hpp"

namespace manikind {
namespace {

struct H5Api {
    decltype(&::H5Aclose) Aclose = nullptr;
    decltype(&::H5Acreate2) Acreate2 = nullptr;
    decltype(&::H5Aget_type) Aget_type = nullptr;
    decltype(&::H5Aopen_by_name) Aopen_by_name = nullptr;
    decltype(&::H5Aread) Aread = nullptr;
    decltype(&::H5Awrite) Awrite = nullptr;
    decltype(&::H5Dclose) Dclose = nullptr;
    decltype(&::H5Dcreate2) Dcreate2 = nullptr;
    decltype(&::H5Dget_offset) Dget_offset = nullptr;
    decltype(&::H5Dget_space) Dget_space = nullptr;
    decltype(&::H5Dget_type) Dget_type = nullptr;
    decltype(&::H5Dopen2) Dopen2 = nullptr;
    decltype(&::H5Dread) Dread = nullptr;
    decltype(&::H5Dwrite) Dwrite = nullptr;
    decltype(&::H5Eset_auto2) Eset_auto2 = nullptr;
    decltype(&::H5Fclose) Fclose = nullptr;
    decltype(&::H5Fcreate) Fcreate = nullptr;
    decltype(&::H5Fflush) Fflush = nullptr;
    decltype(&::H5Fopen) Fopen = nullptr;
    decltype(&::H5Gclose) Gclose = nullptr;
    decltype(&::H5Gcreate2) Gcreate2 = nullptr;
    decltype(&::H5Gopen2) Gopen2 = nullptr;
    decltype(&::H5Ldelete) Ldelete = nullptr;
    decltype(&::H5Pclose) Pclose = nullptr;
    decltype(&::H5Pcreate) Pcreate = nullptr;
    decltype(&::H5Pset_alloc_time) Pset_alloc_time = nullptr;
    decltype(&::H5Pset_fill_time) Pset_fill_time = nullptr;
    decltype(&::H5Pset_layout) Pset_layout = nullptr;
    decltype(&::H5Lexists) Lexists = nullptr;
    decltype(&::H5Sclose) Sclose = nullptr;
    decltype(&::H5Screate) Screate = nullptr;
    decltype(&::H5Screate_simple) Screate_simple = nullptr;
    decltype(&::H5Sget_simple_extent_npoints) Sget_simple_extent_npoints = nullptr;
    decltype(&::H5Tclose) Tclose = nullptr;
    decltype(&::H5Tcopy) Tcopy = nullptr;
    decltype(&::H5Tget_class) Tget_class = nullptr;
    decltype(&::H5Tget_size) Tget_size = nullptr;
    decltype(&::H5Tis_variable_str) Tis_variable_str = nullptr;
    decltype(&::H5Tset_cset) Tset_cset = nullptr;
    decltype(&::H5Tset_size) Tset_size = nullptr;
    decltype(&::H5Tset_strpad) Tset_strpad = nullptr;
    decltype(&::H5dont_atexit) dont_atexit = nullptr;
    decltype(&::H5free_memory) free_memory = nullptr;
    // The predefined types: global ids the library sets in H5open (the header's H5T_NATIVE_DOUBLE
    // and the like are macros that read them).
    hid_t native_double, native_int32, native_int64, native_uint8, c_s1, ieee_f64le, std_i64le;
    hid_t dataset_create;  // the property list class H5P_DATASET_CREATE
};

// HDF5 is loaded by the first HDF5 call, not at start-up (base/lazy_library.hpp). A failed load
// throws from here and is tried again at the next call.
const H5Api& h5() {
    static LazyLibrary library("libmanikind-hdf5.so", "HDF5 (libhdf5, for HDF5 exports)");
    return library.table<H5Api>([](LazyLibrary& l, H5Api& a) {
        MANIKIND_BIND(l, a, Aclose, H5Aclose);
        MANIKIND_BIND(l, a, Acreate2, H5Acreate2);
        MANIKIND_BIND(l, a, Aget_type, H5Aget_type);
        MANIKIND_BIND(l, a, Aopen_by_name, H5Aopen_by_name);
        MANIKIND_BIND(l, a, Aread, H5Aread);
        MANIKIND_BIND(l, a, Awrite, H5Awrite);
        MANIKIND_BIND(l, a, Dclose, H5Dclose);
        MANIKIND_BIND(l, a, Dcreate2, H5Dcreate2);
        MANIKIND_BIND(l, a, Dget_offset, H5Dget_offset);
        MANIKIND_BIND(l, a, Dget_space, H5Dget_space);
        MANIKIND_BIND(l, a, Dget_type, H5Dget_type);
        MANIKIND_BIND(l, a, Dopen2, H5Dopen2);
        MANIKIND_BIND(l, a, Dread, H5Dread);
        MANIKIND_BIND(l, a, Dwrite, H5Dwrite);
        MANIKIND_BIND(l, a, Eset_auto2, H5Eset_auto2);
        MANIKIND_BIND(l, a, Fclose, H5Fclose);
        MANIKIND_BIND(l, a, Fcreate, H5Fcreate);
        MANIKIND_BIND(l, a, Fflush, H5Fflush);
        MANIKIND_BIND(l, a, Fopen, H5Fopen);
        MANIKIND_BIND(l, a, Gclose, H5Gclose);
        MANIKIND_BIND(l, a, Gcreate2, H5Gcreate2);
        MANIKIND_BIND(l, a, Gopen2, H5Gopen2);
        MANIKIND_BIND(l, a, Ldelete, H5Ldelete);
        MANIKIND_BIND(l, a, Pclose, H5Pclose);
        MANIKIND_BIND(l, a, Pcreate, H5Pcreate);
        MANIKIND_BIND(l, a, Pset_alloc_time, H5Pset_alloc_time);
        MANIKIND_BIND(l, a, Pset_fill_time, H5Pset_fill_time);
        MANIKIND_BIND(l, a, Pset_layout, H5Pset_layout);
        MANIKIND_BIND(l, a, Lexists, H5Lexists);
        MANIKIND_BIND(l, a, Sclose, H5Sclose);
        MANIKIND_BIND(l, a, Screate, H5Screate);
        MANIKIND_BIND(l, a, Screate_simple, H5Screate_simple);
        MANIKIND_BIND(l, a, Sget_simple_extent_npoints, H5Sget_simple_extent_npoints);
        MANIKIND_BIND(l, a, Tclose, H5Tclose);
        MANIKIND_BIND(l, a, Tcopy, H5Tcopy);
        MANIKIND_BIND(l, a, Tget_class, H5Tget_class);
        MANIKIND_BIND(l, a, Tget_size, H5Tget_size);
        MANIKIND_BIND(l, a, Tis_variable_str, H5Tis_variable_str);
        MANIKIND_BIND(l, a, Tset_cset, H5Tset_cset);
        MANIKIND_BIND(l, a, Tset_size, H5Tset_size);
        MANIKIND_BIND(l, a, Tset_strpad, H5Tset_strpad);
        MANIKIND_BIND(l, a, dont_atexit, H5dont_atexit);
        MANIKIND_BIND(l, a, free_memory, H5free_memory);
        // No library clean-up at exit, asked before anything initialises it (see library_setup).
        a.dont_atexit();
        decltype(&::H5open) open = nullptr;
        l.bind(open, "H5open");
        if (open() < 0) throw UserError("HDF5: the library did not initialise (H5open failed)", "missing_library");
        const auto global = [&](const char* name) { return *static_cast<const hid_t*>(l.symbol(name)); };
        a.native_double = global("H5T_NATIVE_DOUBLE_g");
        a.native_int32 = global("H5T_NATIVE_INT32_g");
        a.native_int64 = global("H5T_NATIVE_INT64_g");
        a.native_uint8 = global("H5T_NATIVE_UINT8_g");
        a.c_s1 = global("H5T_C_S1_g");
        a.ieee_f64le = global("H5T_IEEE_F64LE_g");
        a.std_i64le = global("H5T_STD_I64LE_g");
        a.dataset_create = global("H5P_CLS_DATASET_CREATE_ID_g");
    });
}

// H5F_ACC_TRUNC and H5F_ACC_RDONLY without their macros' calls into the library (H5check, H5open).
constexpr unsigned kAccTrunc = 0x0002u;
constexpr unsigned kAccReadOnly = 0x0000u;
constexpr unsigned kAccReadWrite = 0x0001u;


// Before HDF5 calls: errors become UserErrors, not stderr dumps. And (in h5(), once) no library
// clean-up at exit. A file whose write failed (a full disk) stays open inside HDF5
// 1.10, and its exit handler then flushes it again and crashes (rc 139 after the right error
// message); every file we keep is closed explicitly and checked, so nothing is lost by skipping it.
void library_setup() {
    h5().Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // per thread where the library is thread-safe
}

// One HDF5 identifier, closed with the function of its kind.
class Handle {
public:
    Handle(hid_t id, herr_t (*closer)(hid_t)) : id_(id), close_(closer) {}
    Handle(Handle&& other) noexcept : id_(other.id_), close_(other.close_) { other.id_ = -1; }
    Handle(const Handle&) = delete;
    Handle& operator=(const Handle&) = delete;
    Handle& operator=(Handle&& other) noexcept {
        if (this != &other) {
            if (id_ >= 0) close_(id_);
            id_ = other.id_;
            close_ = other.close_;
            other.id_ = -1;
        }
        return *this;
    }
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
    explicit Writer(const std::filesystem::path& path) : path_(path), file_(create(path), h5().Fclose) {}

    hid_t root() const { return file_.get(); }

    Handle group(hid_t parent, const std::string& name) {
        Handle g(h5().Gcreate2(parent, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), h5().Gclose);
        check(g.ok(), "creating group " + name);
        return g;
    }

    template <typename T>
    void dataset(hid_t parent, const std::string& name, const std::vector<T>& values, hid_t memory_type,
                 const std::string& unit = {}) {
        const hsize_t dims[1] = {values.size()};
        Handle space(h5().Screate_simple(1, dims, nullptr), h5().Sclose);
        Handle set(h5().Dcreate2(parent, name.c_str(), memory_type, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                   h5().Dclose);
        check(set.ok(), "creating dataset " + name);
        if (!values.empty())
            check(h5().Dwrite(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) >= 0, "writing " + name);
        if (!unit.empty()) attribute(set.get(), "unit", unit);
    }

    // A scalar fixed-length string dataset (Octave's load reads it as char; it does not read
    // variable-length strings).
    void string_dataset(hid_t parent, const std::string& name, const std::string& text) {
        Handle type(fixed_string_type(text.size()), h5().Tclose);
        Handle space(h5().Screate(H5S_SCALAR), h5().Sclose);
        Handle set(h5().Dcreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                   h5().Dclose);
        check(set.ok(), "creating dataset " + name);
        check(h5().Dwrite(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, text.data()) >= 0, "writing " + name);
    }

    // The same kind of dataset, `size` bytes, whose bytes the caller writes itself once the file
    // is closed, at the returned file offset: contiguous, its space allocated now and never
    // filled by the library, so the region is the string's raw bytes (H5Dget_offset, the
    // library's direct access to a contiguous dataset). A reader sees an ordinary string.
    std::uint64_t reserve_string_dataset(hid_t parent, const std::string& name, std::size_t size) {
        Handle type(fixed_string_type(size), h5().Tclose);
        Handle space(h5().Screate(H5S_SCALAR), h5().Sclose);
        Handle create(h5().Pcreate(h5().dataset_create), h5().Pclose);
        check(create.ok() && h5().Pset_layout(create.get(), H5D_CONTIGUOUS) >= 0 &&
                  h5().Pset_alloc_time(create.get(), H5D_ALLOC_TIME_EARLY) >= 0 &&
                  h5().Pset_fill_time(create.get(), H5D_FILL_TIME_NEVER) >= 0,
              "setting up dataset " + name);
        Handle set(h5().Dcreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, create.get(), H5P_DEFAULT),
                   h5().Dclose);
        check(set.ok(), "creating dataset " + name);
        const haddr_t at = h5().Dget_offset(set.get());
        check(at != HADDR_UNDEF, "placing dataset " + name);
        return static_cast<std::uint64_t>(at);
    }

    // Fixed-length strings, one per element, padded with NUL (a char matrix in Octave).
    void strings_dataset(hid_t parent, const std::string& name, const std::vector<std::string>& texts) {
        std::size_t width = 1;
        for (const auto& t : texts) width = std::max(width, t.size());
        std::vector<char> packed(texts.size() * width, '\0');
        for (std::size_t i = 0; i < texts.size(); ++i) std::copy(texts[i].begin(), texts[i].end(), packed.begin() + static_cast<long>(i * width));
        Handle type(fixed_string_type(width), h5().Tclose);
        const hsize_t dims[1] = {texts.size()};
        Handle space(h5().Screate_simple(1, dims, nullptr), h5().Sclose);
        Handle set(h5().Dcreate2(parent, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                   h5().Dclose);
        check(set.ok(), "creating dataset " + name);
        if (texts.empty()) return;  // an empty column: created, nothing to write
        check(h5().Dwrite(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, packed.data()) >= 0, "writing " + name);
    }

    // Variable-length UTF-8: h5py gives str (a fixed-length one reads as bytes), MATLAB's
    // h5readatt a char row; Octave's load skips attributes whatever their type.
    void attribute(hid_t object, const std::string& name, const std::string& text) {
        Handle type(h5().Tcopy(h5().c_s1), h5().Tclose);
        h5().Tset_size(type.get(), H5T_VARIABLE);
        h5().Tset_cset(type.get(), H5T_CSET_UTF8);
        Handle space(h5().Screate(H5S_SCALAR), h5().Sclose);
        Handle attr(h5().Acreate2(object, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), h5().Aclose);
        check(attr.ok(), "creating attribute " + name);
        const char* data = text.c_str();
        check(h5().Awrite(attr.get(), type.get(), &data) >= 0, "writing attribute " + name);
    }

    void attribute(hid_t object, const std::string& name, double value) {
        Handle space(h5().Screate(H5S_SCALAR), h5().Sclose);
        Handle attr(h5().Acreate2(object, name.c_str(), h5().ieee_f64le, space.get(), H5P_DEFAULT, H5P_DEFAULT), h5().Aclose);
        check(attr.ok(), "creating attribute " + name);
        check(h5().Awrite(attr.get(), h5().native_double, &value) >= 0, "writing attribute " + name);
    }

    void attribute(hid_t object, const std::string& name, std::int64_t value) {
        Handle space(h5().Screate(H5S_SCALAR), h5().Sclose);
        Handle attr(h5().Acreate2(object, name.c_str(), h5().std_i64le, space.get(), H5P_DEFAULT, H5P_DEFAULT), h5().Aclose);
        check(attr.ok(), "creating attribute " + name);
        check(h5().Awrite(attr.get(), h5().native_int64, &value) >= 0, "writing attribute " + name);
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
    // Closes the file and opens it again: HDF5 keeps every object's metadata it wrote in a cache
    // of up to 32 MB per open file, so a long campaign's export grew to 73 MB at 45 trials. The
    // caller has closed every object in it.
    void reopen() {
        close();
        errno = 0;
        const hid_t f = h5().Fopen(path_.c_str(), kAccReadWrite, H5P_DEFAULT);
        check(f >= 0, "opening the file again");
        file_ = Handle(f, h5().Fclose);
    }

private:
    static hid_t create(const std::filesystem::path& path) {
        library_setup();
        errno = 0;
        const hid_t f = h5().Fcreate(path.c_str(), kAccTrunc, H5P_DEFAULT, H5P_DEFAULT);
        if (f < 0) throw UserError(fmt::format("{}: cannot create the HDF5 file", path.string()));
        return f;
    }
    // Labelled ASCII although the bytes are UTF-8 (°, ²): Octave 7's load refuses a dataset
    // whose character set is UTF-8, and passes the bytes through unchanged either way.
    static hid_t fixed_string_type(std::size_t size) {
        const hid_t t = h5().Tcopy(h5().c_s1);
        h5().Tset_size(t, std::max<std::size_t>(size, 1));
        h5().Tset_strpad(t, H5T_STR_NULLPAD);
        return t;
    }

    std::filesystem::path path_;
    Handle file_;
};

// Counts what is written to it and keeps none of it.
class CountingBuffer : public std::streambuf {
public:
    std::size_t bytes = 0;

protected:
    int_type overflow(int_type c) override {
        if (!traits_type::eq_int_type(c, traits_type::eof())) ++bytes;
        return traits_type::not_eof(c);
    }
    std::streamsize xsputn(const char*, std::streamsize n) override {
        bytes += static_cast<std::size_t>(n);
        return n;
    }
};

// Results per case in columns: what a script plots without parsing JSON; the whole `manikin
// analyze --json` document beside them (analysis_json: 14 MB of text at 450 trials). Its text
// is never held: its length is counted first (analysis::write_json into a counter), its place
// in the file reserved here, and its bytes streamed there once the file is closed (finish).
// Returns that place.
std::uint64_t write_results(Writer& w, hid_t parent, const analysis::CampaignResult& result, std::size_t json_bytes) {
    Handle results = w.group(parent, "results");
    const std::uint64_t json_at = w.reserve_string_dataset(results.get(), "analysis_json", json_bytes);
    std::vector<std::int32_t> case_ids, n;
    std::vector<double> q, u95, k, u_a, u_b;
    for (const auto& c : result.cases) {
        case_ids.push_back(c.case_id);
        n.push_back(c.n_replicates);
        const auto& e = c.whole_body.q;
        q.push_back(e.value);
        u95.push_back(e.U);
        k.push_back(e.k);
        u_a.push_back(std::isfinite(e.u_a) ? e.u_a : std::numeric_limits<double>::quiet_NaN());  // as the JSON: null -> NaN
        u_b.push_back(e.u_b);
    }
    w.dataset(results.get(), "case", case_ids, h5().native_int32);
    w.dataset(results.get(), "n_replicates", n, h5().native_int32);
    w.dataset(results.get(), "q_wb_w_m2", q, h5().native_double, "W/m²");
    w.dataset(results.get(), "u95_w_m2", u95, h5().native_double, "W/m²");
    w.dataset(results.get(), "k", k, h5().native_double, "1");
    w.dataset(results.get(), "u_a_w_m2", u_a, h5().native_double, "W/m²");
    w.dataset(results.get(), "u_b_w_m2", u_b, h5().native_double, "W/m²");
    w.attribute(results.get(), "heat_flux_sign", std::string(analysis::kHeatFluxSign));
    return json_at;
}

// The root's attributes, the zone map and the notebook: everything but the trials and results.
void write_metadata(Writer& w, const analysis::Campaign& c) {
    w.attribute(w.root(), "format", std::string(kHdf5Format));
    w.attribute(w.root(), "campaign", c.name);
    w.attribute(w.root(), "heat_flux_sign", std::string(analysis::kHeatFluxSign));
    for (const auto& [key, value] : c.provenance) w.attribute(w.root(), key, value);
    // Clothing tests: the standards the campaign chose, as campaign.json's `standards`.
    for (const auto& [test, standard] : c.standards) w.attribute(w.root(), test + "_standard", standard);

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
        w.dataset(zones.get(), "zone", number, h5().native_int32);
        w.dataset(zones.get(), "area_m2", area, h5().native_double, "m²");
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

}

// One trial's group under /trials, with a dataset per column and per recorded channel of `c`.
void write_trial_group(Writer& w, hid_t trials, const analysis::Campaign& c, const analysis::TrialInfo& info,
                       const analysis::TrialData& data) {
    const auto columns_of = [&](const analysis::TrialData& td) {
        return analysis::trial_csv_columns(c.zone_map, !td.air_speed_m_s.empty(), !td.wall_temp_c.empty());
    };
    const auto& d = data;
    const auto& t = info;
    if (h5().Lexists(trials, t.id.c_str(), H5P_DEFAULT) > 0)  // written again with the campaign's final channels
        w.check(h5().Ldelete(trials, t.id.c_str(), H5P_DEFAULT) >= 0, "replacing trial " + t.id);
    Handle g = w.group(trials, t.id);
    w.attribute(g.get(), "case", static_cast<std::int64_t>(t.case_id));
    w.attribute(g.get(), "replicate", static_cast<std::int64_t>(t.replicate));
    if (t.skin_setpoint_c) w.attribute(g.get(), "skin_setpoint_c", *t.skin_setpoint_c);
    if (t.wettedness) w.attribute(g.get(), "wettedness", *t.wettedness);
    // The chamber's setpoints beside the enclosure's readings (a trial group says what was asked).
    if (t.chamber_setpoint_temp_c) w.attribute(g.get(), "chamber_setpoint_temp_c", *t.chamber_setpoint_temp_c);
    if (t.chamber_setpoint_rh_pct) w.attribute(g.get(), "chamber_setpoint_rh_pct", *t.chamber_setpoint_rh_pct);
    if (!t.ensemble.empty()) w.attribute(g.get(), "ensemble", t.ensemble);
    if (!t.test.empty()) w.attribute(g.get(), "test", t.test);
    if (!t.control.empty()) w.attribute(g.get(), "control", t.control);
    // The room the trial's case stated ([[cases.local]]), as campaign.json's trials[].local (JSON text).
    if (const auto room = analysis::local_room_json(c.zone_map, t.local); !room.empty()) w.attribute(g.get(), "local", room.dump());
    if (t.partial) w.attribute(g.get(), "partial", std::int64_t{1});  // exported while running
    if (t.t0_utc_ns) w.attribute(g.get(), "t0_utc", analysis::iso_utc_ms(*t.t0_utc_ns));
    w.dataset(g.get(), "t_s", d.t_s, h5().native_double, "s");
    if (!d.utc_ns.empty()) w.dataset(g.get(), "utc_ns", d.utc_ns, h5().native_int64, "ns since 1970-01-01T00:00:00Z");
    // The analysis columns, named as in the CSV.
    std::vector<const std::vector<double>*> series{&d.air_temp_c, &d.air_rh_pct};
    std::vector<std::string> units{"°C", "%"};
    if (!d.air_speed_m_s.empty()) series.push_back(&d.air_speed_m_s), units.emplace_back("m/s");
    if (!d.wall_temp_c.empty()) series.push_back(&d.wall_temp_c), units.emplace_back("°C");
    for (const auto& z : d.skin_temp_c) series.push_back(&z), units.emplace_back("°C");
    for (const auto& z : d.heat_flux_w_m2) series.push_back(&z), units.emplace_back("W/m²");
    const auto names = columns_of(d);
    for (std::size_t i = 0; i < series.size(); ++i) w.dataset(g.get(), names[i + 1], *series[i], h5().native_double, units[i]);
    for (std::size_t k = 0; k < c.channels.size() && k < d.channel_values.size(); ++k) {
        const auto& ch = c.channels[k];
        w.dataset(g.get(), ch.column(), d.channel_values[k], h5().native_double, ch.unit);
        w.dataset(g.get(), ch.column() + ".q", d.channel_quality[k], h5().native_uint8,
                  "quality: 0 good, 1 stale, 2 out of range, 3 communication error, 255 no sample");
    }
}

// Opens `file` read-only and one dataset in it.
struct DatasetReader {
    Handle file;
    Handle set;
    DatasetReader(const std::filesystem::path& path, const std::string& name)
        : file((library_setup(), h5().Fopen(path.c_str(), kAccReadOnly, H5P_DEFAULT)), h5().Fclose),
          set(file.ok() ? h5().Dopen2(file.get(), name.c_str(), H5P_DEFAULT) : -1, h5().Dclose) {
        if (!file.ok()) throw UserError(fmt::format("{}: not an HDF5 file, or unreadable", path.string()));
        if (!set.ok()) throw UserError(fmt::format("{}: no dataset '{}'", path.string(), name));
    }
    std::size_t size() const {
        Handle space(h5().Dget_space(set.get()), h5().Sclose);
        const auto n = h5().Sget_simple_extent_npoints(space.get());
        return n < 0 ? 0 : static_cast<std::size_t>(n);
    }
    template <typename T>
    std::vector<T> read(hid_t memory_type, const std::filesystem::path& path, const std::string& name) const {
        std::vector<T> out(size());
        if (!out.empty() && h5().Dread(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
            throw UserError(fmt::format("{}: cannot read '{}' as the requested type", path.string(), name));
        return out;
    }
};

}  // namespace

struct Hdf5CampaignFile::Impl {
    std::filesystem::path file, partial;
    Writer writer;
    Handle trials;
    bool finished = false;
    Impl(const std::filesystem::path& f, const std::filesystem::path& p)
        : file(f), partial(p), writer(p), trials(writer.group(writer.root(), "trials")) {}
};

Hdf5CampaignFile::Hdf5CampaignFile(const std::filesystem::path& file, const analysis::Campaign& metadata) {
    const std::filesystem::path partial = file.string() + fmt::format(".partial-{}", ::getpid());
    try {
        impl_ = std::make_unique<Impl>(file, partial);
        write_metadata(impl_->writer, metadata);
    } catch (...) {
        impl_.reset();
        std::error_code ignored;
        std::filesystem::remove(partial, ignored);
        throw;
    }
}

Hdf5CampaignFile::~Hdf5CampaignFile() {
    if (!impl_ || impl_->finished) return;
    const auto partial = impl_->partial;
    impl_.reset();  // closes what is open
    std::error_code ignored;
    std::filesystem::remove(partial, ignored);
}

void Hdf5CampaignFile::write_trial(const analysis::Campaign& campaign, const analysis::TrialInfo& info,
                                   const analysis::TrialData& data) {
    write_trial_group(impl_->writer, impl_->trials.get(), campaign, info, data);
    // Memory flat in the number of trials: the file closed and opened again after each trial.
    impl_->writer.check(impl_->trials.close(), "closing group trials");
    impl_->writer.reopen();
    impl_->trials = Handle(h5().Gopen2(impl_->writer.root(), "trials", H5P_DEFAULT), h5().Gclose);
    impl_->writer.check(impl_->trials.ok(), "opening group trials again");
}

void Hdf5CampaignFile::finish(const analysis::CampaignResult& analysis) {
    auto& w = impl_->writer;
    impl_->trials.close();
    CountingBuffer counter;
    {
        std::ostream counting(&counter);
        analysis::write_json(counting, analysis, 0);
    }
    const std::uint64_t json_at = write_results(w, w.root(), analysis, counter.bytes);
    w.check(h5().Fflush(w.root(), H5F_SCOPE_GLOBAL) >= 0, "flushing");
    w.close();
    {
        // The analysis document into the place reserved for it, as it is formatted (memory flat
        // in the number of trials, issue 36). The same result gives the same bytes; the count
        // is checked all the same.
        std::fstream out(impl_->partial, std::ios::in | std::ios::out | std::ios::binary);
        out.seekp(static_cast<std::streamoff>(json_at));
        analysis::write_json(out, analysis, 0);
        out.flush();
        const auto end = out.tellp();
        if (!out || end < 0 || static_cast<std::uint64_t>(end) - json_at != counter.bytes)
            throw UserError(fmt::format("{}: writing the analysis document failed (disk full?)", impl_->partial.string()));
    }
    std::filesystem::rename(impl_->partial, impl_->file);
    impl_->finished = true;
}

void write_campaign_hdf5(const std::filesystem::path& file, const analysis::Campaign& campaign,
                         const analysis::CampaignResult& analysis) {
    Hdf5CampaignFile out(file, campaign);
    for (const auto& t : campaign.trials) out.write_trial(campaign, t.info, t.data);
    out.finish(analysis);
}

void write_teq_hdf5(const std::filesystem::path& file, const analysis::teq::Result& r, const nlohmann::json& doc) {
    // `manikin teq --hdf5` (docs/formats.md section 7.3): a group per case with the zones', the
    // regions' and the whole body's teq and its uncertainty as columns, and the JSON document
    // beside them. `file` is written whole (the caller's staging file, renamed into place).
    Writer w(file);
    w.attribute(w.root(), "format", std::string(kTeqHdf5Format));
    w.attribute(w.root(), "campaign", r.campaign);
    w.attribute(w.root(), "calibration_campaign", r.calibration_campaign);
    w.attribute(w.root(), "method", std::string(r.options.curved_h ? "h from the calibration's curve" : "constant h_cal (ISO 14505-2)"));
    w.attribute(w.root(), "neutral_ranges", r.ranges.source);
    w.string_dataset(w.root(), "teq_json", doc.dump());
    Handle cases = w.group(w.root(), "cases");
    for (const auto& c : r.cases) {
        Handle g = w.group(cases.get(), fmt::format("case_{:03d}", c.case_id));
        w.attribute(g.get(), "case", static_cast<std::int64_t>(c.case_id));
        w.attribute(g.get(), "replicates", static_cast<std::int64_t>(c.replicates));
        w.attribute(g.get(), "air_temp_c", c.air_temp_c);
        w.attribute(g.get(), "wall_temp_c", c.wall_temp_c);
        w.attribute(g.get(), "air_speed_m_s", c.air_speed_m_s);
        auto table = [&](const std::string& name, const std::vector<analysis::teq::PartTeq>& parts) {
            Handle t = w.group(g.get(), name);
            std::vector<std::string> names, verdicts;
            std::vector<double> teq, u_a, u_b, u_c, k, u95, skin, q, area;
            for (const auto& p : parts) {
                names.push_back(p.name);
                verdicts.push_back(p.verdict);
                teq.push_back(p.teq.value);
                u_a.push_back(p.teq.u_a);
                u_b.push_back(p.teq.u_b);
                u_c.push_back(p.teq.u_c);
                k.push_back(p.teq.k);
                u95.push_back(p.teq.U95);
                skin.push_back(p.skin_temp_c);
                q.push_back(p.q_w_m2);
                area.push_back(p.area_m2);
            }
            w.strings_dataset(t.get(), "name", names);
            w.dataset(t.get(), "teq_c", teq, h5().native_double, "°C");
            w.dataset(t.get(), "u_a_c", u_a, h5().native_double, "K");
            w.dataset(t.get(), "u_b_c", u_b, h5().native_double, "K");
            w.dataset(t.get(), "u_c_c", u_c, h5().native_double, "K");
            w.dataset(t.get(), "k", k, h5().native_double);
            w.dataset(t.get(), "U95_c", u95, h5().native_double, "K");
            w.dataset(t.get(), "skin_temp_c", skin, h5().native_double, "°C");
            w.dataset(t.get(), "q_w_m2", q, h5().native_double, "W/m²");
            w.dataset(t.get(), "area_m2", area, h5().native_double, "m²");
            w.strings_dataset(t.get(), "verdict", verdicts);
        };
        table("zones", c.zones);
        table("regions", c.regions);
        table("whole_body", {c.whole_body});
    }
    w.check(cases.close(), "closing group cases");
    w.close();
}

std::vector<double> hdf5_read_doubles(const std::filesystem::path& file, const std::string& dataset) {
    return DatasetReader(file, dataset).read<double>(h5().native_double, file, dataset);
}

std::vector<std::int64_t> hdf5_read_int64(const std::filesystem::path& file, const std::string& dataset) {
    return DatasetReader(file, dataset).read<std::int64_t>(h5().native_int64, file, dataset);
}

std::vector<std::uint8_t> hdf5_read_uint8(const std::filesystem::path& file, const std::string& dataset) {
    return DatasetReader(file, dataset).read<std::uint8_t>(h5().native_uint8, file, dataset);
}

std::string hdf5_read_string(const std::filesystem::path& file, const std::string& dataset) {
    const DatasetReader r(file, dataset);
    Handle type(h5().Dget_type(r.set.get()), h5().Tclose);
    if (h5().Tget_class(type.get()) != H5T_STRING || h5().Tis_variable_str(type.get()) > 0)
        throw UserError(fmt::format("{}: '{}' is not a fixed-length string", file.string(), dataset));
    std::string out(h5().Tget_size(type.get()), '\0');
    if (h5().Dread(r.set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
        throw UserError(fmt::format("{}: cannot read '{}'", file.string(), dataset));
    if (const auto nul = out.find('\0'); nul != std::string::npos) out.resize(nul);
    return out;
}

std::string hdf5_read_string_attribute(const std::filesystem::path& file, const std::string& object,
                                       const std::string& attribute) {
    library_setup();
    Handle f(h5().Fopen(file.c_str(), kAccReadOnly, H5P_DEFAULT), h5().Fclose);
    if (!f.ok()) throw UserError(fmt::format("{}: not an HDF5 file, or unreadable", file.string()));
    Handle attr(h5().Aopen_by_name(f.get(), object.c_str(), attribute.c_str(), H5P_DEFAULT, H5P_DEFAULT), h5().Aclose);
    if (!attr.ok()) throw UserError(fmt::format("{}: no attribute '{}' on '{}'", file.string(), attribute, object));
    Handle type(h5().Aget_type(attr.get()), h5().Tclose);
    if (h5().Tget_class(type.get()) != H5T_STRING || h5().Tis_variable_str(type.get()) <= 0)
        throw UserError(fmt::format("{}: attribute '{}' is not a variable-length string", file.string(), attribute));
    char* text = nullptr;
    if (h5().Aread(attr.get(), type.get(), &text) < 0 || !text)
        throw UserError(fmt::format("{}: cannot read attribute '{}'", file.string(), attribute));
    std::string out(text);
    h5().free_memory(text);
    return out;
}

}  // namespace manikind
