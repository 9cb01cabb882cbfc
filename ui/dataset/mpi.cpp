#include "ui/dataset/mpi.h"

// The C interface only (Open MPI's and MPICH's deprecated C++ bindings need their own
// library).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include <chrono>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include "tissue/base/error.h"

namespace sonotrace::dataset {

namespace {

constexpr int kRequestTag = 1, kShardTag = 2;
constexpr uint64_t kNone = ~uint64_t(0), kFailed = ~uint64_t(0) - 1;

// MPI initialised for the lifetime of the object; only one thread makes MPI calls at a
// time (rank 0's dispatcher, the main thread before and after it).
class MpiSession {
  public:
    MpiSession() {
        int provided = 0;
        MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided);
        MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
        MPI_Comm_size(MPI_COMM_WORLD, &size_);
    }
    ~MpiSession() { MPI_Finalize(); }
    MpiSession(const MpiSession&) = delete;
    MpiSession& operator=(const MpiSession&) = delete;
    int rank() const { return rank_; }
    int size() const { return size_; }

  private:
    int rank_ = 0, size_ = 1;
};

// True on every rank if it is true on all of them.
bool all(bool ok) {
    int mine = ok ? 1 : 0, everyone = 0;
    MPI_Allreduce(&mine, &everyone, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    return everyone == 1;
}

// What went wrong on one rank: an InputError's parts, or (`input` false) a bug's message.
struct RankError {
    std::string source, field, detail;
    bool input = true;
};

// Runs `work`, keeping what it throws as a RankError instead of letting it leave the rank
// while the others wait for it.
template <typename Work>
std::optional<RankError> capture(Work&& work) {
    try {
        work();
    } catch (const base::InputError& e) {
        return RankError{e.source(), e.field(), e.detail(), true};
    } catch (const std::filesystem::filesystem_error& e) {
        return RankError{e.path1().string().substr(0, 300), "", e.code().message(), true};
    } catch (const std::exception& e) {
        return RankError{"", "", e.what(), false};
    }
    return std::nullopt;
}

// Collective: if any rank holds an error, the lowest such rank's error reaches every rank
// (one message for the whole job, printed by rank 0 alone).
std::optional<RankError> agree_on_error(const std::optional<RankError>& mine, int rank, int size) {
    int candidate = mine ? rank : size, first = size;
    MPI_Allreduce(&candidate, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (first == size) return std::nullopt;
    RankError error = rank == first ? *mine : RankError{};
    int input = error.input ? 1 : 0;
    MPI_Bcast(&input, 1, MPI_INT, first, MPI_COMM_WORLD);
    error.input = input == 1;
    for (std::string* text : {&error.source, &error.field, &error.detail}) {
        uint64_t length = text->size();
        MPI_Bcast(&length, 1, MPI_UINT64_T, first, MPI_COMM_WORLD);
        text->resize(length);
        MPI_Bcast(text->data(), int(length), MPI_CHAR, first, MPI_COMM_WORLD);
    }
    return error;
}

// Rank 0 reports the job's error; the other ranks return quietly with `failed` set (their
// lines would interleave with rank 0's).
RunReport finish_with(const RankError& error, int rank, RunReport report) {
    if (rank == 0) {
        if (error.input) throw base::InputError(error.source, error.field, error.detail);
        throw std::runtime_error(error.detail);
    }
    report.failed = true;
    return report;
}

}  // namespace

bool launched_by_mpi() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "PMI_RANK"})
        if (std::getenv(name)) return true;
    return false;
}

RunReport make_dataset_mpi(const Spec& spec, const RunOptions& options, int* rank_out) {
    MpiSession mpi;
    if (rank_out) *rank_out = mpi.rank();
    if (mpi.size() == 1) return make_dataset(spec, options);

    // -- every rank loads the sources; rank 0 looks at the directory. Errors reach every
    // rank (a rank that cannot start must not leave the others waiting).
    RunReport report;
    std::vector<uint64_t> missing;
    std::optional<FrameMaker> maker;
    const std::optional<RankError> start_error = capture([&] {
        check_shard_fits_memory(spec);
        if (mpi.rank() == 0)
            missing = missing_shards(spec, options.out_dir, &report.shards_kept, &report.damaged);
        maker.emplace(spec);
    });
    if (const auto error = agree_on_error(start_error, mpi.rank(), mpi.size()))
        return finish_with(*error, mpi.rank(), report);
    // -- rank 0: a dispatcher thread answers the other ranks from the queue that rank 0's
    // own loop also takes from.
    uint64_t total = 0;
    for (uint64_t k : missing) total += spec.frames_in_shard(k);
    std::mutex mutex;
    std::deque<uint64_t> queue(missing.begin(), missing.end());
    uint64_t done = 0;
    bool stopped = false, failed = false;
    auto next = [&]() -> std::optional<uint64_t> {
        std::lock_guard<std::mutex> lock(mutex);
        if (options.stop && options.stop()) stopped = true;
        if (stopped || failed || queue.empty()) return std::nullopt;
        const uint64_t k = queue.front();
        queue.pop_front();
        return k;
    };
    auto count_frames = [&](uint64_t frames) {
        std::lock_guard<std::mutex> lock(mutex);
        done += frames;
        if (options.progress) options.progress(done, total);
    };
    // A rank whose shard fails tells rank 0 (kFailed), which then hands out no more work:
    // every rank finishes its shard in flight and reaches the agreement below.
    std::optional<RankError> error;
    if (mpi.rank() == 0) {
        uint64_t written_elsewhere = 0;
        std::thread dispatcher([&] {
            int finished = 0;
            while (finished < mpi.size() - 1) {
                uint64_t message[2];  // {shard just written, kNone or kFailed; its frames}
                MPI_Status status;
                // Polled, not a blocking receive: Open MPI's blocking calls spin, and this
                // thread shares rank 0's cores with its own shard's frames.
                int waiting = 0;
                MPI_Iprobe(MPI_ANY_SOURCE, kRequestTag, MPI_COMM_WORLD, &waiting, &status);
                if (!waiting) {
                    std::this_thread::sleep_for(std::chrono::milliseconds(2));
                    continue;
                }
                MPI_Recv(message, 2, MPI_UINT64_T, status.MPI_SOURCE, kRequestTag, MPI_COMM_WORLD,
                         &status);
                if (message[0] == kFailed) {
                    std::lock_guard<std::mutex> lock(mutex);
                    failed = true;
                } else if (message[0] != kNone) {
                    ++written_elsewhere;
                    count_frames(message[1]);
                }
                const uint64_t k = next().value_or(kNone);
                if (k == kNone) ++finished;
                MPI_Send(&k, 1, MPI_UINT64_T, status.MPI_SOURCE, kShardTag, MPI_COMM_WORLD);
            }
        });
        while (const auto k = next()) {
            bool complete = false;
            error = capture([&] {
                complete = write_one_shard(*maker, *k, options.out_dir, options.stop,
                                           [&] { count_frames(1); });
            });
            std::lock_guard<std::mutex> lock(mutex);
            if (error) failed = true;
            if (!complete) {
                stopped = stopped || !error;
                break;
            }
            ++report.shards_written;
        }
        dispatcher.join();
        report.shards_written += written_elsewhere;
    } else {
        uint64_t message[2] = {kNone, 0};
        for (;;) {
            MPI_Send(message, 2, MPI_UINT64_T, 0, kRequestTag, MPI_COMM_WORLD);
            uint64_t k = kNone;
            MPI_Recv(&k, 1, MPI_UINT64_T, 0, kShardTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            if (k == kNone) break;
            bool complete = false;
            error = capture(
                [&] { complete = write_one_shard(*maker, k, options.out_dir, options.stop, {}); });
            // Failed: say so, and take the answer (no more work). Stopped: the shard is
            // abandoned; say so by asking once more.
            message[0] = error ? kFailed : complete ? k : kNone;
            message[1] = complete ? spec.frames_in_shard(k) : 0;
        }
    }
    if (const auto job_error = agree_on_error(error, mpi.rank(), mpi.size()))
        return finish_with(*job_error, mpi.rank(), report);
    // -- every rank is done with its shards; rank 0 writes the manifest if all are there.
    report.stopped = !all(!stopped && !(options.stop && options.stop()));
    if (mpi.rank() == 0 && !report.stopped) {
        uint64_t kept = 0;
        if (missing_shards(spec, options.out_dir, &kept).empty())
            report.manifest = write_manifest(spec, options.out_dir);
        else
            report.stopped = true;
    }
    return report;
}

}  // namespace sonotrace::dataset
