#pragma once
// "A run that fails leaves no partial output file behind": outputs are written under a
// hidden temporary name next to their destination and renamed into place together at
// the end. If the transaction is destroyed without commit(), the staged files are
// deleted.
#include <cstddef>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace sonotrace::base {

// The path a message should name: for a staged temporary (OutputTransaction::stage) its
// final path, otherwise `path` itself. Users never see the hidden names.
std::string output_name(const std::string& path);

// Writes `size` bytes to `path` (created or truncated) and closes it, checking every call:
// a full disk or an I/O error throws InputError naming output_name(path) and removes the
// file, instead of leaving a truncated file reported as written. `synced`: the data reach
// the disk (fsync) before it returns, for a file a later run will trust once renamed
// (a power cut could otherwise leave the new name on an empty file).
enum class Durability { buffered, synced };
void write_file(const std::string& path, const void* data, std::size_t size,
                Durability durability = Durability::buffered);
// Makes the renames and creations in directory `dir` durable (fsync of the directory).
void sync_directory(const std::string& dir);

// How a staged temporary names the process that writes it: "PID.HOST", HOST 16 hex digits
// of this machine's name. A later run removes a temporary whose process is gone only when
// HOST is its own: on a directory shared between hosts, a process id of another host
// means nothing here.
std::string temporary_owner(long pid);

class OutputTransaction {
  public:
    OutputTransaction() = default;
    OutputTransaction(const OutputTransaction&) = delete;
    OutputTransaction& operator=(const OutputTransaction&) = delete;
    ~OutputTransaction();

    // Returns the temporary path to write instead of `final_path`: same directory and
    // file name (so the extension still selects the format), hidden, unique per process.
    // Creates the directory if needed, and removes the temporaries that runs no longer
    // alive left there. Throws if this transaction already stages `final_path` (two
    // outputs of one name: one would silently replace the other).
    std::string stage(const std::string& final_path);
    // Renames every staged file to its final path, all or nothing: if a rename fails, the
    // files already placed are removed and the ones they replaced restored, then it throws.
    void commit();
    // The final paths staged so far.
    std::vector<std::string> final_paths() const;

  private:
    std::vector<std::pair<std::string, std::string>> staged_;  // {temporary, final}
    std::vector<std::string> cleaned_;        // directories whose stale temporaries were removed
    std::set<std::string> canonical_finals_;  // the final paths staged, canonical
    bool committed_ = false;
};

}  // namespace sonotrace::base
