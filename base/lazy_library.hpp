#pragma once
// A system library loaded when a command first needs it, not when the program starts (issue 36:
// `manikin --version` spent 80 % of its 8 ms loading HDF5, libpq, libcurl and libcrypto, which
// only export, archive, notifications and fingerprints use).
//
// Each library is reached through a module of ours: an empty shared object linked against it
// (modules/CMakeLists.txt), so the linker, not this code, names the library's soname. The module
// is looked for beside the running program, then in ../lib/manikind; dlsym on the module's handle
// searches the library it depends on. The functions keep their header's types (decltype of the
// declaration), so a call through the table is checked by the compiler like a direct call.
#include <mutex>
#include <string>

namespace manikind {

class LazyLibrary {
public:
    // `module_file`: e.g. "libmanikind-hdf5.so"; `what`: how a message names it ("HDF5 (libhdf5)").
    LazyLibrary(std::string module_file, std::string what);
    LazyLibrary(const LazyLibrary&) = delete;
    LazyLibrary& operator=(const LazyLibrary&) = delete;

    // The address of `symbol`, loading the module at the first call. UserError (status 2, code
    // "missing_library") naming the module, where it was looked for and the loader's reason.
    void* symbol(const char* name);

    // Binds `slot` (a function pointer of the symbol's declared type) to `name`.
    template <typename Fn>
    void bind(Fn& slot, const char* name) {
        void* address = symbol(name);
        static_assert(sizeof(Fn) == sizeof(void*));
        __builtin_memcpy(&slot, &address, sizeof address);  // POSIX: a data pointer holds a function's address
    }

    // Where the program looks for modules: the directory of /proc/self/exe.
    static std::string program_directory();

    // The table `Api` of a library's functions, bound by `binder` at the first call (each type's
    // table once per process); a failed load throws here and is tried again at the next call.
    template <typename Api>
    const Api& table(void (*binder)(LazyLibrary&, Api&)) {
        static const Api api = [&] {
            Api a{};
            binder(*this, a);
            return a;
        }();
        return api;
    }

private:
    void load();
    std::string module_file_, what_;
    std::once_flag once_;
    void* handle_ = nullptr;
};

}  // namespace manikind

// Binds table.member to the library function `fn` with fn's own type.
#define MANIKIND_BIND(library, table, member, fn) (library).bind<decltype(&::fn)>((table).member, #fn)
