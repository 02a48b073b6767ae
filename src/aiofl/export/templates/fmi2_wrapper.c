/*
 * fmi2_wrapper.c: FMI 2.0 co-simulation interface of an exported aiofl controller.
 *
 * Hand-written, static (shipped in the aiofl package, copied unchanged into the FMU's
 * sources/).  It includes fmu_adapter.h, generated at export, which defines:
 *
 *   FMU_GUID, FMU_TS, FMU_N_IN            the model's GUID, the sample time [s], the number of
 *                                         Real inputs (y, r and r_1..r_rho with exact
 *                                         derivatives)
 *   fmu_ctl_state, fmu_ctl_params         the controller's state and (per-instance) parameters
 *   fmu_ctl_defaults(p)                   p = the exported design
 *   fmu_ctl_start(s, p, y0, mode)         start modes 0 bumpless, 1 zero, 2 output
 *   FMU_START_DEFAULT                     the default start mode (the config's eso.init)
 *   fmu_ctl_step(s, p, r, y)              one sample; r = r, r_1, ... (FMU_N_IN - 1 values)
 *   FMU_N_CALC, fmu_calc_values[]         calculated parameters (Ts first), read only
 *   FMU_N_TUN, fmu_tun_defaults[],        tunable parameters: defaults, lower bounds, whether
 *   fmu_tun_min[], fmu_tun_nonzero[],     0 is refused, and the setter writing one into the
 *   fmu_ctl_set(p, i, v)                  instance's parameter copy
 *
 * Value references, Real: 0 = y, 1 = r, 2.. = r_1..r_rho (inputs); FMU_N_IN = u (output);
 * then the FMU_N_CALC calculated parameters, then the FMU_N_TUN tunable parameters.
 * Integer: 0 = start (0 bumpless, 1 zero, 2 output; fixed: set it before initialisation).
 *
 * Timing.  The controller samples at t_k = t_start + k Ts (t_start from fmi2SetupExperiment),
 * and only at communication points: a doStep from t to t + h that would pass a sample
 * instant strictly inside (t, t + h) is refused with fmi2Error (the inputs there are not
 * known), so h = Ts (the default experiment's step size) or any h that lands on every t_k
 * (h = Ts/n) works; between samples u is held.  The sample at a communication point t_k is
 * taken from the inputs set there: u is direct feedthrough (fmi2GetReal of u after setting
 * y and r at t_k returns u_k; setting them again recomputes it from the state before the
 * sample), and fmi2DoStep(t_k, h) commits it.  A master that reads u only after doStep
 * (FMPy's simulate_fmu) reads, at t_(k+1), the u_k held over [t_k, t_(k+1)).
 *
 * Faults (the controller's policy, aiofl_controller.h; the same in aiofl.DiscreteController):
 * a y or r that is not finite or beyond +-1e30, or an update that overflows, leaves the
 * controller as it was and holds u at its last value; from then on every fmi2DoStep and
 * every fmi2GetReal of u returns fmi2Warning (logged once, category logStatusWarning), u
 * held, until fmi2Reset.  Refused with fmi2Error: fmi2SetupExperiment with a start time
 * that is not finite or beyond 1e9 Ts (the sample instants t0 + k Ts would lose their
 * resolution), or a stop time before it; a tunable parameter whose value makes a
 * coefficient of the controller non-finite (e.g. sef.omega_c = 1e308).
 */

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_adapter.h"

#define FMU_VR_U ((fmi2ValueReference)FMU_N_IN)
#define FMU_VR_CALC ((fmi2ValueReference)(FMU_N_IN + 1))
#define FMU_VR_TUN ((fmi2ValueReference)(FMU_N_IN + 1 + FMU_N_CALC))
#define FMU_N_REAL (FMU_N_IN + 1 + FMU_N_CALC + FMU_N_TUN)

typedef enum { PH_INSTANTIATED, PH_INIT, PH_STEP, PH_TERMINATED, PH_ERROR } fmu_phase;

typedef struct {
    fmi2CallbackFunctions cb;
    char name[128];
    int logging;
    fmu_phase phase;
    fmi2Real t0, time, tol;
    long next_k;      /* index of the next sample instant t0 + k Ts not yet committed */
    int pending;      /* the FMU is at sample instant next_k */
    int inputs_set;   /* the inputs were set at this communication point */
    int computed;     /* u holds the sample at this instant, from s_base */
    int fault_logged; /* the controller's fault was logged */
    fmi2Integer start;
    fmi2Real in[FMU_N_IN];
    fmi2Real u;
    fmi2Real tun[FMU_N_TUN > 0 ? FMU_N_TUN : 1];
    fmu_ctl_params p;
    fmu_ctl_state s_base;  /* the state before the sample at this instant */
    fmu_ctl_state s;       /* the state after it */
} fmu_inst;

static void fmu_log(fmu_inst *c, fmi2Status status, const char *category, const char *fmt, ...)
{
    char msg[512];
    va_list ap;
    if (c == NULL || c->cb.logger == NULL) return;
    if (!c->logging && status == fmi2OK) return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    c->cb.logger(c->cb.componentEnvironment, c->name, status, category, "%s", msg);
}

static fmi2Status fmu_fail(fmu_inst *c, const char *fn, const char *why)
{
    fmu_log(c, fmi2Error, "logStatusError", "%s: %s", fn, why);
    return fmi2Error;
}

static void fmu_defaults(fmu_inst *c)
{
    int i;
    fmu_ctl_defaults(&c->p);
    for (i = 0; i < FMU_N_TUN; ++i) c->tun[i] = fmu_tun_defaults[i];
    for (i = 0; i < FMU_N_IN; ++i) c->in[i] = 0.0;
    c->u = 0.0;
    c->start = FMU_START_DEFAULT;
    c->phase = PH_INSTANTIATED;
    c->t0 = c->time = 0.0;
    c->next_k = 0;
    c->pending = c->inputs_set = c->computed = c->fault_logged = 0;
    memset(&c->s_base, 0, sizeof c->s_base);
    memset(&c->s, 0, sizeof c->s);
}

/* u at the current sample instant from the current inputs (initialisation: from the start
   the inputs define) */
static void fmu_sample(fmu_inst *c)
{
    if (c->computed) return;
    if (c->phase == PH_INIT) fmu_ctl_start(&c->s_base, &c->p, c->in[0], (int)c->start);
    c->s = c->s_base;
    c->u = fmu_ctl_step(&c->s, &c->p, c->in + 1, c->in[0]);
    c->computed = 1;
}

/* fmi2Warning (logged once) while the controller holds u after a fault, else fmi2OK */
static fmi2Status fmu_fault_status(fmu_inst *c, const char *fn)
{
    if (!fmu_ctl_fault(&c->s)) return fmi2OK;
    if (!c->fault_logged) {
        c->fault_logged = 1;
        fmu_log(c, fmi2Warning, "logStatusWarning",
                "%s: the measurement y or the reference is not finite or beyond +-1e30, or the "
                "update overflowed: u is held at %.17g until fmi2Reset",
                fn, c->u);
    }
    return fmi2Warning;
}

/* ------------------------------------------------------------------ common functions */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t n,
                               const fmi2String categories[])
{
    (void)n;
    (void)categories;
    if (comp == NULL) return fmi2Error;
    ((fmu_inst *)comp)->logging = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String location, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    fmu_inst *c;
    (void)location;
    (void)visible;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL)
        return NULL;
    if (instanceName == NULL) instanceName = "";
    if (fmuType != fmi2CoSimulation || fmuGUID == NULL || strcmp(fmuGUID, FMU_GUID) != 0) {
        if (functions->logger != NULL)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                              "logStatusError",
                              fmuType != fmi2CoSimulation
                                  ? "fmi2Instantiate: this FMU supports co-simulation only"
                                  : "fmi2Instantiate: wrong GUID (not this FMU's "
                                    "modelDescription.xml)");
        return NULL;
    }
    c = (fmu_inst *)functions->allocateMemory(1, sizeof(fmu_inst));
    if (c == NULL) return NULL;
    memset(c, 0, sizeof *c);
    c->cb = *functions;
    strncpy(c->name, instanceName, sizeof c->name - 1);
    c->logging = loggingOn ? 1 : 0;
    c->tol = 1e-6 * FMU_TS;
    fmu_defaults(c);
    return c;
}

void fmi2FreeInstance(fmi2Component comp)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c != NULL) c->cb.freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    fmu_inst *c = (fmu_inst *)comp;
    (void)toleranceDefined;
    (void)tolerance;
    if (c == NULL) return fmi2Error;
    if (c->phase != PH_INSTANTIATED)
        return fmu_fail(c, "fmi2SetupExperiment", "only after fmi2Instantiate or fmi2Reset");
    if (!isfinite(startTime) || fabs(startTime) > 1e9 * FMU_TS)
        return fmu_fail(c, "fmi2SetupExperiment",
                        "startTime: allowed a finite time, |startTime| <= 1e9 Ts");
    if (stopTimeDefined && !(isfinite(stopTime) && stopTime >= startTime))
        return fmu_fail(c, "fmi2SetupExperiment", "stopTime: allowed a finite time >= startTime");
    c->t0 = c->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c == NULL) return fmi2Error;
    if (c->phase != PH_INSTANTIATED)
        return fmu_fail(c, "fmi2EnterInitializationMode", "not in the instantiated state");
    c->phase = PH_INIT;
    c->computed = 0;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c == NULL) return fmi2Error;
    if (c->phase != PH_INIT)
        return fmu_fail(c, "fmi2ExitInitializationMode", "not in initialization mode");
    c->computed = 0;
    fmu_sample(c);  /* starts the controller from the inputs set so far (y0 = y) */
    c->phase = PH_STEP;
    c->time = c->t0;
    c->next_k = 0;
    c->pending = 1;
    c->inputs_set = 1;  /* the inputs at t_start are the ones set before */
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c == NULL) return fmi2Error;
    c->phase = PH_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c == NULL) return fmi2Error;
    fmu_defaults(c);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[])
{
    fmu_inst *c = (fmu_inst *)comp;
    size_t i;
    fmi2Status status = fmi2OK;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) return fmi2Error;
    for (i = 0; i < nvr; ++i) {
        fmi2ValueReference r = vr[i];
        if (r < FMU_N_IN) {
            value[i] = c->in[r];
        } else if (r == FMU_VR_U) {
            if (c->phase == PH_INIT || (c->phase == PH_STEP && c->pending && c->inputs_set))
                fmu_sample(c);
            value[i] = c->u;
            if (c->computed || c->phase == PH_STEP) status = fmu_fault_status(c, "fmi2GetReal");
        } else if (r < FMU_VR_TUN) {
            value[i] = fmu_calc_values[r - FMU_VR_CALC];
        } else if (r < FMU_N_REAL) {
            value[i] = c->tun[r - FMU_VR_TUN];
        } else {
            return fmu_fail(c, "fmi2GetReal", "unknown value reference");
        }
    }
    return status;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    fmu_inst *c = (fmu_inst *)comp;
    size_t i;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) return fmi2Error;
    if (c->phase == PH_TERMINATED || c->phase == PH_ERROR)
        return fmu_fail(c, "fmi2SetReal", "the FMU is terminated");
    for (i = 0; i < nvr; ++i) { /* check all before changing any */
        fmi2ValueReference r = vr[i];
        fmi2Real v = value[i];
        if (r >= FMU_VR_TUN && r < FMU_N_REAL) {
            int k = (int)(r - FMU_VR_TUN);
            fmu_ctl_params trial = c->p;
            if (!isfinite(v) || v < fmu_tun_min[k] || (fmu_tun_nonzero[k] && v == 0.0))
                return fmu_fail(c, "fmi2SetReal", "a parameter value out of its range");
            fmu_ctl_set(&trial, k, v);
            if (!fmu_ctl_params_finite(&trial))
                return fmu_fail(c, "fmi2SetReal",
                                "a parameter value too large: the controller's coefficients "
                                "it sets are not finite");
        } else if (r >= FMU_N_IN) {
            return fmu_fail(c, "fmi2SetReal", "not an input or a tunable parameter");
        }
    }
    for (i = 0; i < nvr; ++i) {
        fmi2ValueReference r = vr[i];
        if (r < FMU_N_IN) {
            c->in[r] = value[i];
            c->inputs_set = 1;
        } else {
            int k = (int)(r - FMU_VR_TUN);
            c->tun[k] = value[i];
            fmu_ctl_set(&c->p, k, value[i]);
        }
        c->computed = 0;  /* a sample at this instant is taken again (from s_base) */
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    fmu_inst *c = (fmu_inst *)comp;
    size_t i;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) return fmi2Error;
    for (i = 0; i < nvr; ++i) {
        if (vr[i] != 0) return fmu_fail(c, "fmi2GetInteger", "unknown value reference");
        value[i] = c->start;
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    fmu_inst *c = (fmu_inst *)comp;
    size_t i;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) return fmi2Error;
    for (i = 0; i < nvr; ++i) {
        if (vr[i] != 0) return fmu_fail(c, "fmi2SetInteger", "unknown value reference");
        if (c->phase != PH_INSTANTIATED && c->phase != PH_INIT)
            return fmu_fail(c, "fmi2SetInteger", "start is fixed: set it before initialisation");
        if (value[i] < 0 || value[i] > 2)
            return fmu_fail(c, "fmi2SetInteger", "start: allowed 0 bumpless, 1 zero, 2 output");
    }
    for (i = 0; i < nvr; ++i) c->start = value[i];
    c->computed = 0;
    return fmi2OK;
}

static fmi2Status fmu_no_variables(fmi2Component comp, size_t nvr, const char *fn)
{
    if (comp == NULL) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return fmu_fail((fmu_inst *)comp, fn, "this FMU has no variables of this type");
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    (void)vr;
    (void)value;
    return fmu_no_variables(comp, nvr, "fmi2GetBoolean");
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    (void)vr;
    (void)value;
    return fmu_no_variables(comp, nvr, "fmi2SetBoolean");
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    (void)vr;
    (void)value;
    return fmu_no_variables(comp, nvr, "fmi2GetString");
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    (void)vr;
    (void)value;
    return fmu_no_variables(comp, nvr, "fmi2SetString");
}

/* canGetAndSetFMUstate, canSerializeFMUstate, providesDirectionalDerivative: false */
fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state)
{
    (void)state;
    return fmu_fail((fmu_inst *)comp, "fmi2GetFMUstate", "not supported");
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state)
{
    (void)state;
    return fmu_fail((fmu_inst *)comp, "fmi2SetFMUstate", "not supported");
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state)
{
    (void)state;
    return fmu_fail((fmu_inst *)comp, "fmi2FreeFMUstate", "not supported");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size)
{
    (void)state;
    (void)size;
    return fmu_fail((fmu_inst *)comp, "fmi2SerializedFMUstateSize", "not supported");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[],
                                 size_t size)
{
    (void)state;
    (void)bytes;
    (void)size;
    return fmu_fail((fmu_inst *)comp, "fmi2SerializeFMUstate", "not supported");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state)
{
    (void)bytes;
    (void)size;
    (void)state;
    return fmu_fail((fmu_inst *)comp, "fmi2DeSerializeFMUstate", "not supported");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vu[],
                                        size_t nu, const fmi2ValueReference vk[], size_t nk,
                                        const fmi2Real dvk[], fmi2Real dvu[])
{
    (void)vu;
    (void)nu;
    (void)vk;
    (void)nk;
    (void)dvk;
    (void)dvu;
    return fmu_fail((fmu_inst *)comp, "fmi2GetDirectionalDerivative", "not supported");
}

/* ------------------------------------------------------------------ co-simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[])
{
    (void)vr;
    (void)order;
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fmu_fail((fmu_inst *)comp, "fmi2SetRealInputDerivatives",
                    "not supported (canInterpolateInputs = false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[])
{
    size_t i;
    (void)vr;
    (void)order;
    if (comp == NULL) return fmi2Error;
    for (i = 0; i < nvr; ++i) value[i] = 0.0;  /* u is piecewise constant */
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    fmu_inst *c = (fmu_inst *)comp;
    long k_after;
    fmi2Real t_next;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL) return fmi2Error;
    if (c->phase != PH_STEP) return fmu_fail(c, "fmi2DoStep", "not in step mode");
    if (!(h >= 0.0) || fabs(t - c->time) > c->tol)
        return fmu_fail(c, "fmi2DoStep",
                        "currentCommunicationPoint is not the FMU's time, or a negative step");
    k_after = c->pending ? c->next_k + 1 : c->next_k;
    t_next = c->t0 + (fmi2Real)k_after * FMU_TS;
    if (t + h > t_next + c->tol) {
        fmu_log(c, fmi2Error, "logStatusError",
                "fmi2DoStep: the step from t = %.17g to %.17g passes the sample instant "
                "t = %.17g: the controller samples y and r only at communication points; use "
                "a step size of Ts = %.17g s or one that lands on every multiple of Ts",
                t, t + h, t_next, FMU_TS);
        return fmi2Error;
    }
    if (c->pending) {  /* commit the sample at this instant */
        fmu_sample(c);
        c->s_base = c->s;
        c->pending = 0;
        c->next_k = k_after;
    }
    c->time = t + h;
    c->inputs_set = 0;
    if (fabs(c->time - t_next) <= c->tol) {  /* at the next sample instant */
        c->time = t_next;
        c->pending = 1;
        c->computed = 0;
    }
    return fmu_fault_status(c, "fmi2DoStep");
}

fmi2Status fmi2CancelStep(fmi2Component comp)
{
    return fmu_fail((fmu_inst *)comp, "fmi2CancelStep", "doStep is synchronous");
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s;
    (void)value;
    (void)comp;
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c == NULL || s != fmi2LastSuccessfulTime) return fmi2Discard;
    *value = c->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)comp;
    (void)s;
    (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value)
{
    fmu_inst *c = (fmu_inst *)comp;
    if (c == NULL || s != fmi2Terminated) return fmi2Discard;
    *value = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value)
{
    (void)comp;
    (void)s;
    (void)value;
    return fmi2Discard;
}
